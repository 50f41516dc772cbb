"""Rules are code (issue 26): an author's rule set cannot run arbitrary Java on the server.

Each probe below, if it ever ran, would write a marker file on this host. For an author every probe
is refused — at deploy, validate, try and test — with the file, line and column of the name, before
anything compiles: the marker never appears and the compile cache never saw the text. A developer
deploys the same probes, and firing them writes the marker (so each probe is a real one). The
shipped rule sets, the DSL and decision-table examples and the docs' DRL pass the policy for an author.
"""

from __future__ import annotations

import re
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from gateway.engine import compiler
from gateway.engine.policy import RulePolicy
from gateway.engine.ruleset import content_hash, read_folder

PROJECT = Path(__file__).resolve().parents[2]
TOKENS = "tok-dev:developer:dora,tok-author:author:alice,tok-caller:caller:bob"
DEV = {"Authorization": "Bearer tok-dev"}
AUTHOR = {"Authorization": "Bearer tok-author"}
CALLER = {"Authorization": "Bearer tok-caller"}

TYPES = """package org.printeps.probe;
import org.printeps.gateway.Actions;
global Actions actions;
declare Customer
    id : String
    age : int
end
"""

WRITE = 'java.nio.file.Files.writeString(java.nio.file.Path.of("MARKER"), "pwned")'
MKDIR = 'new java.io.File("MARKER").mkdir()'  # no checked exception: usable where an expression is


def _rule(then: str = 'actions.say("pepper", "hi");', when: str = "$c : Customer()", head: str = "") -> str:
    return f'package org.printeps.probe;\n{head}\nrule "probe"\nwhen\n    {when}\nthen\n    {then}\nend\n'


# shape -> (probe.drl, the name the refusal must carry, its line in probe.drl)
PROBES: dict[str, tuple[str, str, int]] = {
    "then-part": (_rule(WRITE + ";"), "java.nio.file.Files", 7),
    "import": (_rule('Files.writeString(Path.of("MARKER"), "pwned");',
                     head="import java.nio.file.Files;\nimport java.nio.file.Path;"), "java.nio.file.Files", 2),
    "function": ('package org.printeps.probe;\n'
                 'function void leak(String p) {\n'
                 '    try { java.nio.file.Files.writeString(java.nio.file.Path.of(p), "pwned"); } catch (Exception e) { }\n}\n'
                 'rule "probe"\nwhen\n    $c : Customer()\nthen\n    leak("MARKER");\nend\n', "java.nio.file.Files", 3),  # the call in the function's body
    "eval": (_rule("actions.say(\"pepper\", \"hi\");", when=f"$c : Customer()\n    eval( {MKDIR} )"),
             "java.io.File", 6),
    "from": (_rule("actions.say(\"pepper\", \"hi\");",
                   when=f"$c : Customer()\n    $p : Object() from {MKDIR}"), "java.io.File", 6),
    "static call": (_rule('Runtime.getRuntime().exec(new String[] {"touch", "MARKER"}).waitFor();'),
                    "java.lang.Runtime", 7),
    "reflection": (_rule('Class.forName("java.nio.file.Files").getMethod("writeString", java.nio.file.Path.class, '
                         'CharSequence.class, java.nio.file.OpenOption[].class).invoke(null, '
                         'java.nio.file.Path.of("MARKER"), "pwned", new java.nio.file.OpenOption[0]);'),
                   "java.lang.Class", 7),
}


def probe_files(shape: str, marker: Path) -> dict[str, str]:
    drl = PROBES[shape][0].replace("MARKER", str(marker))
    return {"types.drl": TYPES, "probe.drl": drl}


@pytest.fixture(scope="module")
def api(api_settings, api_gateway) -> Iterator[TestClient]:
    """An app with the three roles, over the session's gateway."""
    from gateway.api.main import create_app

    with TestClient(create_app(api_gateway, api_settings.api.model_validate({"tokens": TOKENS}))) as c:
        yield c


def _slug(shape: str) -> str:
    return "probe-" + shape.replace(" ", "-").replace("-part", "")


def _assert_refused_here(body: dict, shape: str, errors: list[dict] | None = None) -> None:
    _, name, line = PROBES[shape]
    errors = errors if errors is not None else body["errors"]
    first = errors[0]
    assert first["file"] == "probe.drl" and first["line"] == line and first["column"] > 0, errors
    assert name in first["message"] and "rule policy" in first["message"], first


@pytest.mark.parametrize("shape", sorted(PROBES))
def test_a_probe_is_refused_for_an_author_everywhere_and_nothing_runs(api, tmp_path, shape):
    marker = tmp_path / "marker"
    files = probe_files(shape, marker)
    name = _slug(shape)

    deployed = api.put(f"/api/rulesets/{name}", json={"files": files}, headers=AUTHOR)
    assert deployed.status_code == 422 and deployed.json()["kind"] == "policy", deployed.text
    _assert_refused_here(deployed.json(), shape)

    validated = api.post(f"/api/rulesets/{name}/validate", json={"files": files}, headers=AUTHOR)
    assert validated.status_code == 200 and validated.json()["ok"] is False
    _assert_refused_here(validated.json(), shape)

    tried = api.post(f"/api/rulesets/{name}/try", json={"files": files, "facts": [{"type": "Customer", "id": "c"}]},
                     headers=AUTHOR)
    assert tried.status_code == 422 and tried.json()["kind"] == "policy", tried.text
    _assert_refused_here(tried.json(), shape)

    scenario = "- name: probe\n  given:\n    - {type: Customer, id: c}\n  expect:\n    fired: [probe]\n"
    tested = api.post(f"/api/rulesets/{name}/test", json={"files": {**files, "tests/probe.yaml": scenario}},
                      headers=CALLER)
    assert tested.status_code == 422 and tested.json()["kind"] == "policy", tested.text

    # the other dry runs of a draft — explain and replay — check it the same way, even for a caller
    explained = api.post(f"/api/rulesets/{name}/explain", json={"files": files, "facts": [{"type": "Customer", "id": "c"}]},
                         headers=CALLER)
    assert explained.status_code == 422 and explained.json()["kind"] == "policy", explained.text
    _assert_refused_here(explained.json(), shape)
    target = api.put("/api/rulesets/policy-replay-target", json={"files": {"types.drl": TYPES, "probe.drl": _rule()}},
                     headers=DEV)
    assert target.status_code in (200, 201), target.text
    replayed = api.post("/api/rulesets/policy-replay-target/replay", json={"files": files}, headers=CALLER)
    assert replayed.status_code == 422 and replayed.json()["kind"] == "policy", replayed.text
    _assert_refused_here(replayed.json(), shape)

    assert not marker.exists()
    assert content_hash(files) not in compiler._cache  # never built: no class of it in any class loader
    assert api.get(f"/api/rulesets/{name}", headers=AUTHOR).status_code == 404  # nothing stored either
    history = api.get(f"/api/rulesets/{name}/history", headers=AUTHOR).json()
    assert [(e["event"], e["author"], e["role"]) for e in history] == [("refused", "alice", "author")]
    assert PROBES[shape][1] in history[0]["comment"] and history[0]["origin"]


@pytest.mark.parametrize("shape", sorted(PROBES))
def test_the_same_probe_deploys_for_a_developer_and_runs(api, tmp_path, shape):
    marker = tmp_path / "marker"
    files = probe_files(shape, marker)
    name = _slug(shape) + "-dev"
    deployed = api.put(f"/api/rulesets/{name}", json={"files": files}, headers=DEV)
    assert deployed.status_code == 201, deployed.text
    fired = api.post(f"/api/rulesets/{name}/fire", json={"facts": [{"type": "Customer", "id": "c"}]}, headers=CALLER)
    assert fired.status_code == 200, fired.text
    deadline = time.monotonic() + 30  # "touch" runs in a process of its own
    while not marker.exists():
        assert time.monotonic() < deadline, f"the {shape} probe did not write {marker}"
        time.sleep(0.05)
    listed = {r["name"]: r for r in api.get("/api/rulesets", headers=CALLER).json()}
    assert listed[name]["policy"] == "developer"
    history = api.get(f"/api/rulesets/{name}/history", headers=CALLER).json()
    assert [(e["event"], e["author"], e["role"]) for e in history] == [("deploy", "dora", "developer")]


def test_a_developers_rule_set_keeps_serving_and_an_authors_changes_are_checked(api, tmp_path):
    name = "probe-kept"
    developers, authors = tmp_path / "developers", tmp_path / "authors"
    assert api.put(f"/api/rulesets/{name}", json={"files": probe_files("then-part", developers)},
                   headers=DEV).status_code == 201
    developers.unlink()  # a deploy warms the new version up on sample facts: a developer's code runs then
    # the author's next deploy of such text is refused with the reasons; the developer's version serves on
    again = api.put(f"/api/rulesets/{name}", json={"files": probe_files("then-part", authors), "comment": "retry"},
                    headers=AUTHOR)
    assert again.status_code == 422 and again.json()["kind"] == "policy"
    assert api.get(f"/api/rulesets/{name}", headers=CALLER).json()["version"] == 1
    # a clean version by the author deploys; rolling back to the developer's version is refused for the author
    clean = {"types.drl": TYPES, "probe.drl": _rule()}
    assert api.put(f"/api/rulesets/{name}", json={"files": clean}, headers=AUTHOR).status_code == 201
    listed = {r["name"]: r for r in api.get("/api/rulesets", headers=CALLER).json()}
    assert listed[name]["policy"] == "author"
    back = api.post(f"/api/rulesets/{name}/rollback", json={"version": 1}, headers=AUTHOR)
    assert back.status_code == 422 and back.json()["kind"] == "policy"
    assert api.get(f"/api/rulesets/{name}", headers=CALLER).json()["version"] == 2
    assert not authors.exists() and not developers.exists()
    assert api.post(f"/api/rulesets/{name}/rollback", json={"version": 1}, headers=DEV).status_code == 200
    assert api.delete(f"/api/rulesets/{name}", headers=AUTHOR).status_code == 200
    history = api.get(f"/api/rulesets/{name}/history", headers=CALLER).json()
    assert [(e["event"], e["author"], e["role"]) for e in history] == [
        ("deploy", "dora", "developer"), ("refused", "alice", "author"), ("deploy", "alice", "author"),
        ("refused", "alice", "author"), ("rollback", "dora", "developer"), ("delete", "alice", "author")]
    assert all(e["origin"] for e in history)


def test_roles_and_the_async_deploy(api, tmp_path):
    assert api.get("/api/whoami", headers=DEV).json() == {"name": "dora", "role": "developer", "auth": "token"}
    assert api.put("/api/rulesets/probe-async", json={"files": probe_files("import", tmp_path / "m")},
                   headers=CALLER).status_code == 403
    job = api.put("/api/rulesets/probe-async?async=true", json={"files": probe_files("import", tmp_path / "m")},
                  headers=AUTHOR)
    assert job.status_code == 202
    deadline = time.monotonic() + 120
    while (state := api.get(job.headers["location"], headers=AUTHOR).json())["status"] in ("queued", "running"):
        assert time.monotonic() < deadline
        time.sleep(0.1)
    assert state["status"] == "failed" and state["error"]["kind"] == "policy", state
    assert state["error"]["errors"][0]["line"] == 2


def test_the_shipped_rule_sets_deploy_for_an_author(api):
    """No false positives: every shipped set (DRL, the DSL reception, the decision-table greetings)."""
    shipped = sorted(p for p in (PROJECT / "rules" / "drl").iterdir() if p.is_dir())
    assert {p.name for p in shipped} >= {"reception", "reception_greetings", "table_service"}
    for folder in shipped:
        files = read_folder(folder)
        answer = api.put(f"/api/rulesets/shipped-{folder.name}", json={"files": files, "force": True}, headers=AUTHOR)
        assert answer.status_code == 201, (folder.name, answer.text)


def test_dsl_and_decision_table_violations_point_at_the_authors_file(api, tmp_path):
    folder = PROJECT / "rules" / "drl" / "reception"
    files = read_folder(folder)
    files["reception.dsl"] += '\n[consequence][]Leak the secrets=System.exit(1);\n'
    lines = files["reception.dslr"].split("\n")
    then = next(n for n, line in enumerate(lines) if line.strip() == "then")
    lines.insert(then + 1, "    Leak the secrets")
    files["reception.dslr"] = "\n".join(lines)
    answer = api.post("/api/rulesets/dsl-probe/validate", json={"files": files}, headers=AUTHOR).json()
    assert answer["ok"] is False
    first = answer["errors"][0]
    assert first["file"] == "reception.dslr" and first["line"] == then + 2 and "java.lang.System" in first["message"]


def test_the_docs_drl_examples_pass_the_policy():
    """Every ```drl block of the docs, checked with the reception's declarations beside it."""
    blocks = []
    for doc in sorted((PROJECT / "docs").glob("*.md")):
        blocks += [(f"{doc.name}#{n}.drl", text) for n, text in
                   enumerate(re.findall(r"```drl\n(.*?)```", doc.read_text(encoding="utf-8"), re.S))]
    assert blocks
    reception = read_folder(PROJECT / "rules" / "drl" / "reception")
    found = RulePolicy().check([("types.drl", reception["types.drl"]), *blocks])
    assert {f: v for f, v in found.items() if v} == {}


def test_import_checks_each_rule_set_for_the_role_it_is_given(api, api_gateway, tmp_path):
    from gateway.runtime.transfer import import_from

    marker = tmp_path / "marker"
    folder = tmp_path / "export" / "rules" / "drl" / "probe-imported"
    folder.mkdir(parents=True)
    for fname, text in probe_files("import", marker).items():
        (folder / fname).write_text(text)
    report = import_from(api_gateway, tmp_path / "export", author="alice", comment="from git", role="author")
    assert len(report) == 1 and report[0][1].startswith("failed: ") and "rule policy" in report[0][1], report
    assert "probe.drl:2:" in report[0][1] and not marker.exists()
    report = import_from(api_gateway, tmp_path / "export", author="ops", comment="from git")  # the machine's rights
    assert report == [("rule set probe-imported", "deployed v1")]
    history = api.get("/api/rulesets/probe-imported/history", headers=CALLER).json()
    assert [(e["event"], e["author"], e["role"]) for e in history] == [("refused", "alice", "author"),
                                                                        ("deploy", "ops", "local")]


def test_an_author_tests_a_stored_developer_version_as_it_serves(api, tmp_path):
    files = probe_files("static call", tmp_path / "marker")
    files["tests/probe.yaml"] = "- name: probe\n  given:\n    - {type: Customer, id: c}\n  expect:\n    fired: [probe]\n"
    assert api.put("/api/rulesets/probe-stored", json={"files": files}, headers=DEV).status_code == 201
    report = api.post("/api/rulesets/probe-stored/test", json={}, headers=AUTHOR)
    assert report.status_code == 200 and report.json()["ok"] is True, report.text
    draft = api.post("/api/rulesets/probe-stored/test", json={"files": files}, headers=AUTHOR)
    assert draft.status_code == 422 and draft.json()["kind"] == "policy"


def test_a_decision_table_cell_that_calls_java_is_refused_at_the_cell(api):
    import sys

    sys.path.insert(0, str(PROJECT / "tests" / "engine"))
    from authoring_samples import ROWS, csv_text, files_with

    rows = [list(r) for r in ROWS]
    rows[0][3] = "2 && java.lang.Runtime.getRuntime() != null"  # the first rule's "At least" cell: row 11, column D
    answer = api.post("/api/rulesets/table-probe/validate", json={"files": files_with("greetings.csv", csv_text(rows))},
                      headers=AUTHOR).json()
    assert answer["ok"] is False
    first = answer["errors"][0]
    assert first["file"] == "greetings.csv" and first["cell"] == "D11" and "java.lang.Runtime" in first["message"], first
    clean = api.post("/api/rulesets/table-probe/validate", json={"files": files_with("greetings.csv", csv_text())},
                     headers=AUTHOR).json()
    assert clean == {"ok": True, "errors": []}
