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
