"""One decision recorder, checked from the source (``ast``): no module but
:mod:`gateway.engine.recorder` builds a decision or writes the ``decisions`` collection.

Why a source scan: a route or engine that builds its own record works, passes its own tests, and
drifts from the others' format the day a field is added (issue 27). Four rules, each naming the
file and line it finds broken:

- only the recorder writes ``decisions`` (a store ``record*`` call, or an insert/update/delete on
  ``db["decisions"]`` / ``db[DECISIONS]``);
- only the recorder builds a decision document (a dict with both ``decision_id`` and
  ``facts_count``);
- only the recorder announces a decision (a ``"fire"`` event to the engine's listeners); the live
  relay hands on other processes' *stored* decisions, already built, and is allowed to;
- outside the engine's decoding (``results``, ``feed``) and the recorder nobody makes a
  ``FireResult`` to record: a route or the stream engine passes what it knows (a session's
  answer, a KIE batch's) to ``engine.recorder``;
- nobody calls ``record_decision``, the engine's entry before the recorder (a branch started
  before it would otherwise merge back a call that fails only when that origin fires).

Together with ``tests/sync/test_decision_format.py`` (a decision of every origin, made through the
gateway's entrances and found in ``decisions`` as pinned), this says every origin records through
the recorder: the documents are there, and nothing else can have written them.
"""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RECORDER = "gateway/engine/recorder.py"
WRITES = {"record", "record_many", "record_strict", "insert_one", "insert_many", "update_one", "update_many",
          "replace_one", "bulk_write", "delete_one", "delete_many", "find_one_and_update", "find_one_and_replace"}
ANNOUNCERS = {"_notify", "notify", "on_engine_event"}
# module -> the rules it may break, and why
ALLOWED: dict[str, set[str]] = {
    RECORDER: {"writes decisions", "builds a decision document", "announces a decision", "makes a FireResult"},
    "gateway/engine/results.py": {"makes a FireResult"},  # decoding the Java side's answer
    "gateway/engine/feed.py": {"makes a FireResult"},  # decoding a stream session's push answer
    "gateway/store/live_relay.py": {"announces a decision"},  # another process's stored decision, to the feed
}


def _names_decisions(node: ast.AST | None) -> bool:
    """``DECISIONS`` or ``"decisions"`` (the collection, by its constant or its name)."""
    return (isinstance(node, ast.Name) and node.id == "DECISIONS") or (
        isinstance(node, ast.Constant) and node.value == "decisions")


def _writes_decisions(call: ast.Call) -> bool:
    func = call.func
    if not isinstance(func, ast.Attribute) or func.attr not in WRITES:
        return False
    on_collection = isinstance(func.value, ast.Subscript) and _names_decisions(func.value.slice)
    return on_collection or bool(call.args and _names_decisions(call.args[0]))


def _announces(call: ast.Call) -> bool:
    func = call.func
    name = func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""
    return name in ANNOUNCERS and bool(call.args) and isinstance(call.args[0], ast.Constant) \
        and call.args[0].value == "fire"


def _makes_fire_result(call: ast.Call) -> bool:
    func = call.func
    return (isinstance(func, ast.Name) and func.id == "FireResult") or (
        isinstance(func, ast.Attribute) and func.attr == "FireResult")


def _old_entry(call: ast.Call) -> bool:
    return isinstance(call.func, ast.Attribute) and call.func.attr == "record_decision"


def _decision_document(node: ast.Dict) -> bool:
    keys = {k.value for k in node.keys if isinstance(k, ast.Constant)}
    return {"decision_id", "facts_count"} <= keys


def breaches(root: Path) -> list[str]:
    """Every broken rule under ``root/gateway``, as ``file:line: what``."""
    found = []
    for path in sorted((root / "gateway").rglob("*.py")):
        where = path.relative_to(root).as_posix()
        allowed = ALLOWED.get(where, set())
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), where)):
            rules = []
            if isinstance(node, ast.Call):
                rules = [rule for rule, hit in (("writes decisions", _writes_decisions(node)),
                                                ("announces a decision", _announces(node)),
                                                ("makes a FireResult", _makes_fire_result(node)),
                                                ("calls record_decision", _old_entry(node))) if hit]
            elif isinstance(node, ast.Dict) and _decision_document(node):
                rules = ["builds a decision document"]
            found += [f"{where}:{node.lineno}: {rule}: record through engine.recorder ({RECORDER}) instead"
                      for rule in rules if rule not in allowed]
    return found


def test_only_the_recorder_builds_and_writes_decisions() -> None:
    assert breaches(ROOT) == []


def test_the_recorder_is_where_the_scan_looks() -> None:
    """The scan would pass vacuously if the recorder moved: it finds the recorder's own write,
    document and announcement (allowed there) when the allowances are lifted."""
    found = set()
    for node in ast.walk(ast.parse((ROOT / RECORDER).read_text(encoding="utf-8"))):
        if isinstance(node, ast.Call):
            found |= {rule for rule, hit in (("writes", _writes_decisions(node)), ("announces", _announces(node)))
                      if hit}
        elif isinstance(node, ast.Dict) and _decision_document(node):
            found.add("document")
    assert found == {"writes", "announces", "document"}


def test_the_scan_finds_each_planted_fault(tmp_path: Path) -> None:
    """A route that records a decision itself, six ways; and one that passes it to the recorder."""
    routes = tmp_path / "gateway" / "api" / "routes"
    routes.mkdir(parents=True)
    faults = {
        "journal.py": "def f(store, doc):\n    store.record(DECISIONS, doc, stored_type='printeps/Decision')\n",
        "direct.py": "def f(db, doc):\n    db['decisions'].insert_one(doc)\n",
        "document.py": "def f(i, facts):\n    return {'decision_id': i, 'facts': facts, 'facts_count': len(facts)}\n",
        "announce.py": "def f(engine, doc):\n    engine._notify('fire', doc)\n",
        "outcome.py": "from gateway.engine import FireResult\n\ndef f(a):\n    return FireResult('r', a.version, [], [])\n",
        "old.py": "def f(engine, result, facts):\n    return engine.record_decision(result, facts, origin='stream')\n",
    }
    for name, text in faults.items():
        (routes / name).write_text(textwrap.dedent(text), encoding="utf-8")
    (routes / "clean.py").write_text(
        "def f(engine, result, facts):\n    return engine.recorder.record(result, facts, origin='rest')\n"
        "def g(db):\n    return db['decisions'].find_one({})\n", encoding="utf-8")
    found = breaches(tmp_path)
    expected = {"journal.py": "writes decisions", "direct.py": "writes decisions",
                "document.py": "builds a decision document", "announce.py": "announces a decision",
                "outcome.py": "makes a FireResult", "old.py": "calls record_decision"}
    assert len(found) == len(expected), found
    for name, rule in expected.items():
        assert any(f"gateway/api/routes/{name}:" in line and rule in line for line in found), (name, found)
    assert not any("clean.py" in line for line in found)
