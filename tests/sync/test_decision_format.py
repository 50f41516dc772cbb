"""The recorded decision's format, pinned origin by origin: what replay, explain, traces, durable
sessions and the workbench read from ``decisions`` in the Information State.

Why a pinned copy: issue 27 moved the record's building into one recorder
(:mod:`gateway.engine.recorder`). The stored document of each origin (a REST fire, a REST
session fire, a KIE batch, a stream binding stateless and stateful, a workflow step, a dialogue
turn, a ROS service fire) must stay exactly what it was, key order included. The expected
documents in ``decision_format.json`` were taken from the tree *before* that change (same test,
same inputs); values that differ at every run (ids, times, the process, generated session ids,
durations) are replaced by what they must look like.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest
from bson import ObjectId
from fastapi.testclient import TestClient

from test_gateway_record import RECEPTION_FACTS, approaching_party, settings_in

EXPECTED = Path(__file__).with_name("decision_format.json")
TRACEPARENT = "00-4bf92f3577b34da6a3ce929d0e0e4736-00f067aa0ba902b7-01"
AT = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z$")


def normalised(doc: dict[str, Any], sessions: dict[str, str]) -> dict[str, Any]:
    """``doc`` as stored, with run-dependent values replaced by their shape (checked here)."""
    out = dict(doc)
    assert isinstance(out["_id"], str) and ObjectId.is_valid(out["_id"]) and out["_id"] == out["decision_id"]
    out["_id"] = out["decision_id"] = "<ObjectId text>"
    assert AT.match(out["at"]), out["at"]
    out["at"] = "<ISO-8601 ms Z>"
    assert out["process"] and isinstance(out["process"], str)
    out["process"] = "<process>"
    assert isinstance(out["duration_ms"], float) and out["duration_ms"] >= 0
    out["duration_ms"] = "<float>"
    meta = dict(out["_meta"])
    for key in ("inserted_at", "process", "inserted_by"):  # inserted_by: the process (host:pid)
        if key in meta:
            meta[key] = f"<{key}>"
    out["_meta"] = meta
    context = dict(out["context"])
    if context.get("session") in sessions:
        context["session"] = sessions[context["session"]]
    out["context"] = context
    if out["origin"] == "stream" and out["correlation_id"]:
        out["correlation_id"] = re.sub(r"@\d+$", "@<window end>", out["correlation_id"])
    if out["origin"] == "workflow":
        run_id = context["run_id"]
        assert out["correlation_id"].startswith(f"{run_id}/")
        context["run_id"] = "<run id>"
        out["correlation_id"] = out["correlation_id"].replace(run_id, "<run id>", 1)
    return out


@pytest.fixture(scope="module")
def recorded(tmp_path_factory, mongo) -> dict[str, dict[str, Any]]:
    """One decision of each origin, made through the gateway's own entrances, as stored."""
    from gw_testing import built_gateway

    tmp = tmp_path_factory.mktemp("format")
    with built_gateway(settings_in(tmp), mongo, tmp) as gateway:
        http = TestClient(gateway.app)
        ids: dict[str, str] = {}
        sessions: dict[str, str] = {}
        rest = http.post("/api/rulesets/reception/fire", json={"facts": RECEPTION_FACTS},
                         headers={"traceparent": TRACEPARENT})
        assert rest.status_code == 200, rest.text
        ids["rest fire"] = rest.json()["decision_id"]

        created = http.post("/api/rulesets/reception/sessions", json={"durable": False})
        assert created.status_code == 201, created.text
        sessions[created.json()["id"]] = "<rest session>"
        fired = http.post(f"/api/rulesets/reception/sessions/{created.json()['id']}/facts",
                          json={"facts": RECEPTION_FACTS, "fire": True}, headers={"X-Request-ID": "session-req"})
        assert fired.status_code == 201, fired.text
        ids["rest session fire"] = fired.json()["decision_id"]

        kie = http.post("/kie-server/services/rest/server/containers/instances/reception", json={"commands": [
            {"insert": {"object": {"Customer": {"id": "k", "entrance": "entrance", "age": 8}}}},
            {"insert": {"object": {"Entrance": {"id": "entrance", "number_of_customers": 1}}}},
            {"fire-all-rules": {}}]}, headers={"X-Request-ID": "kie-req"})
        assert kie.json()["type"] == "SUCCESS", kie.text
        ids["kie batch"] = next(r["value"] for r in kie.json()["result"]["execution-results"]["results"]
                                if r["key"] == "decision-id")

        ros = gateway.engine.fire("reception", RECEPTION_FACTS, origin="ros", correlation_id="ros-req",
                                  context={"service": "fire_business_rules"})  # what gateway.ros.bridge passes
        ids["ros fire"] = ros.decision_id

        events: list[dict[str, Any]] = []
        gateway.streams.subscribe(events.append)
        for message in approaching_party():
            assert http.post("/api/streams", json=message).status_code == 200
        stateless = [e for e in events if e["kind"] == "actions"]
        assert stateless, events
        ids["stream binding"] = stateless[0]["decision_id"]

        query = "CustomerDetectionQuery"
        binding = http.get(f"/api/queries/{query}").json()["binding"]
        bound = http.put(f"/api/queries/{query}/rules", json={**binding, "mode": "stateful"})
        assert bound.status_code == 200, bound.text
        events.clear()
        for message in approaching_party(t0_ms=60_000):
            assert http.post("/api/streams", json=message).status_code == 200
        stateful = [e for e in events if e["kind"] == "actions"]
        assert stateful, events
        ids["stream binding, stateful"] = stateful[0]["decision_id"]

        run = http.post("/api/workflows/greeting/run", json={"inputs": {}})
        assert run.status_code == 200, run.text

        turn = http.post("/api/dialogue/turns", json={"conversation": "format-1", "text": "Two green teas, please",
                                                      "table": "table1"})
        assert turn.status_code == 200, turn.text
        ids["dialogue turn"] = turn.json()["decision_id"]

        assert gateway.store.flush(10)
        coll = gateway.store.db["decisions"]
        docs = {name: coll.find_one({"_id": ObjectId(i)}) for name, i in ids.items()}
        workflow = list(coll.find({"origin": "workflow"}).sort("_id", 1).limit(1))
        assert workflow, "the greeting workflow's first step fires the reception rules"
        docs["workflow step"] = workflow[0]
        for name, doc in docs.items():
            assert doc is not None, f"the {name} decision is not in the Information State"
            stateful_session = (doc.get("context") or {}).get("session")
            if name == "stream binding, stateful" and stateful_session:
                sessions[stateful_session] = "<stream session>"
        out = {}
        for name, doc in docs.items():
            doc = dict(doc)
            doc["_id"] = str(doc["_id"])
            out[name] = json.loads(json.dumps(normalised(doc, sessions), default=str))
        return out


ORIGINS = ["rest fire", "rest session fire", "kie batch", "ros fire", "stream binding", "stream binding, stateful",
           "workflow step", "dialogue turn"]


@pytest.mark.parametrize("origin", ORIGINS)
def test_a_decision_is_stored_exactly_as_before(recorded, origin):
    expected = json.loads(EXPECTED.read_text(encoding="utf-8"))[origin]
    got = recorded[origin]
    assert list(got) == list(expected), f"{origin}: the document's keys (and their order) changed"
    assert list(got["_meta"]) == list(expected["_meta"]), f"{origin}: the _meta keys changed"
    assert got == expected
