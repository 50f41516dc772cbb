"""The one decision recorder on its own (no JVM, no store): what it builds from what callers pass.

The stored format of each origin is pinned end to end by ``tests/sync/test_decision_format.py``;
these check the recorder's own rules: the id it sets, the facts it cuts, and the two session
shapes (a REST session's last fire, a KIE batch's fires together; no fire, no decision)."""

from __future__ import annotations

from typing import Any

from bson import ObjectId

from gateway.engine.recorder import DecisionRecorder
from gateway.engine.results import FireResult
from gateway.engine.session import BatchAnswer


def recorder(max_facts: int = 1000) -> tuple[DecisionRecorder, list[dict[str, Any]]]:
    heard: list[dict[str, Any]] = []
    return DecisionRecorder(lambda kind, doc: heard.append({"kind": kind, **doc}), max_facts=max_facts), heard


def answer(*fires: dict[str, Any], fact_count: int = 3) -> BatchAnswer:
    results = [{"i": 0, "op": "insert", "handles": ["h"]}] + [{"i": i + 1, "op": "fire", "fire": f}
                                                              for i, f in enumerate(fires)]
    return BatchAnswer(results, 0, fact_count, False, 4, 1.5)


def test_a_decision_gets_an_id_and_its_facts_are_cut_with_their_count_kept() -> None:
    rec, heard = recorder(max_facts=2)
    result = FireResult("r", 3, [{"module": "say"}], [{"rule": "a", "facts": []}], fire_count=1, duration_ms=0.5)
    facts = [{"type": "T", "id": i} for i in range(5)]
    decision_id = rec.record(result, facts, origin="stream", correlation_id="q@10", context={"query": "q"})
    assert result.decision_id == decision_id and ObjectId.is_valid(decision_id)
    doc = heard[0]
    assert doc["kind"] == "fire" and doc["_id"] == doc["decision_id"] == decision_id
    assert doc["facts"] == facts[:2] and doc["facts_count"] == 5
    assert (doc["origin"], doc["correlation_id"], doc["fired"], doc["context"]) == ("stream", "q@10", ["a"], {"query": "q"})


def test_a_rest_session_fire_is_the_batch_s_last_fire_on_the_facts_it_inserted() -> None:
    rec, heard = recorder()
    commands = [{"op": "insert", "facts": [{"type": "T", "id": 1}]}, {"op": "fire", "max": -1}]
    last = {"actions": [{"module": "say"}], "fired": [{"rule": "b"}], "fireCount": 1}
    result = rec.session_fire("r", commands, answer({"actions": [], "fired": [{"rule": "a"}], "fireCount": 1}, last),
                              duration_ms=2.0, origin="rest", context={"session": "s1"})
    assert (result.ruleset, result.version, result.fire_count, result.actions) == ("r", 4, 1, [{"module": "say"}])
    assert heard[0]["fired"] == ["b"] and heard[0]["facts"] == [{"type": "T", "id": 1}]
    assert heard[0]["decision_id"] == result.decision_id and heard[0]["duration_ms"] == 2.0


def test_a_kie_batch_is_all_its_fires_and_no_fire_is_no_decision() -> None:
    rec, heard = recorder()
    assert rec.batch("r", answer(), [], origin="kie") is None and heard == []
    two = answer({"actions": [{"module": "a"}], "fired": [{"rule": "x"}], "fireCount": 1},
                 {"actions": [{"module": "b"}], "fired": [{"rule": "y"}, {"rule": "z"}], "fireCount": 2})
    decision_id = rec.batch("r", two, [{"type": "T"}], origin="kie", context={"lookup": None, "session": None})
    doc = heard[0]
    assert doc["decision_id"] == decision_id
    assert (doc["fired"], doc["fire_count"], doc["duration_ms"]) == (["x", "y", "z"], 3, 1.5)
    assert doc["actions"] == [{"module": "a"}, {"module": "b"}]


class Journal:
    """A stand-in for the Information State's decision record: what the recorder hands it."""

    def __init__(self) -> None:
        self.kept: list[dict[str, Any]] = []
        self.store = self

    def remember(self, doc: dict[str, Any]) -> None:
        self.kept.append(doc)

    def record(self, collection: str, doc: dict[str, Any], **_: Any) -> None:
        assert collection == "decisions" and doc is self.kept[-1]


def test_a_decision_nobody_journals_or_hears_gets_its_id_and_no_document() -> None:
    """Why: building the document was most of the recording's cost on every in-process fire, for nobody."""
    heard: list[dict[str, Any]] = []
    listening = [False]
    rec = DecisionRecorder(lambda kind, doc: heard.append(doc), heard=lambda: listening[0])
    built: list[str] = []
    document = rec.document
    rec.document = lambda decision_id, *rest: built.append(decision_id) or document(decision_id, *rest)  # type: ignore[method-assign]
    result = FireResult("r", 1, [], [{"rule": "a"}], fire_count=1, duration_ms=0.1)
    decision_id = rec.record(result, [{"type": "T"}], origin="api")
    assert ObjectId.is_valid(decision_id) and result.decision_id == decision_id
    assert built == [] and heard == []
    journal = Journal()
    rec.journal_to(journal)  # type: ignore[arg-type]
    journalled = rec.record(result, [{"type": "T"}], origin="api")
    assert built == [journalled] and [d["_id"] for d in journal.kept] == [journalled]
    rec.enabled = False  # store.record_fires off: nothing journalled; a listener still hears
    listening[0] = True
    live = rec.record(result, [{"type": "T"}], origin="api")
    assert built == [journalled, live] and heard[-1]["_id"] == live and len(journal.kept) == 1
