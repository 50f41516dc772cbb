"""Stream replay over REST: recorded sensor input re-run through a candidate query, rule set or
mapping (real JVM, real MongoDB-protocol server, the real ROS ingress code path without a ROS
graph). The messages are taken in by the gateway's own :class:`Ingress` (which records them as
the ROS node does); the expected changes are computed here from the generated distances."""

from __future__ import annotations

import random

import pytest

from gateway.config import RosSubscription
from gateway.ros.ingress import Ingress

from test_jobs import ASYNC, follow

STREAM = "http://printeps.org/test/replay-stream"
TOPIC = "replay_test_objects"
MAPPING = "replay_test_object"
RULESET = "replay-s"
T0 = 1_790_000_000_000  # event time of the first window (ms, a multiple of 1000)
N = 60  # one message per second, one window each
P = "http://printeps.org/cafe/entrance/"


def query(limit: float) -> str:
    return f"""PARAM ?limit = {limit}
REGISTER QUERY ReplayNear AS
PREFIX printeps: <{P}>
SELECT ?person ?d
FROM STREAM <{STREAM}> [RANGE 1s TUMBLING]
WHERE {{ ?person printeps:distance ?d . FILTER(?d < ?limit) }}
"""


RULES = """package org.printeps.streamreplaytest;

import org.printeps.gateway.Actions;

global Actions actions;

declare Near
    person : String
    distance : double
end

rule "Greet"
when
    $n : Near( distance < CLOSE )
then
    actions.say("pepper", "Hello " + $n.getPerson());
end

rule "Wave"
when
    $n : Near( distance >= CLOSE )
then
    actions.say("pepper", "Wave at " + $n.getPerson());
end
"""

BINDING = {"ruleset": RULESET, "fact_type": "Near", "fields": {"person": "person", "distance": "d"}}


def rules(close: float) -> dict[str, str]:
    return {"near.drl": RULES.replace("CLOSE", str(close))}


def iso(ms: int) -> str:
    from datetime import datetime, timezone

    return datetime.fromtimestamp(ms / 1000, timezone.utc).isoformat().replace("+00:00", "Z")


PERIOD = {"since": iso(T0), "until": iso(T0 + N * 1000), "streams": [STREAM]}


@pytest.fixture(scope="module")
def recorded(client, api_gateway):
    """N messages (one person each, at a random distance) taken in by the ingress, live query and
    rules in place; returns the distances in window order."""
    subscription = RosSubscription(topic=TOPIC, type="printeps_interfaces/msg/TeahouseObject", stream=STREAM,
                                   mapping=MAPPING)
    api_gateway.settings.ros.subscriptions.append(subscription)
    try:
        spec = {"subject": "printeps:{id}", "fields": {"distance": "printeps:distance"}}
        assert client.put(f"/api/mappings/{MAPPING}", json={"spec": spec}).status_code == 201
        assert client.put(f"/api/rulesets/{RULESET}", json={"files": rules(2.0)}).status_code == 201
        r = client.post("/api/queries", json={"query": query(3.3), "rules": BINDING, "replace": True})
        assert r.status_code == 201, r.text
        rng = random.Random(6)
        distances = [round(rng.uniform(1.0, 4.0), 2) for _ in range(N)]
        ingress = Ingress([subscription], api_gateway.mapper, api_gateway.streams, api_gateway.store)
        for k, d in enumerate(distances):
            stamp = T0 + k * 1000 + 500
            report = ingress.handle(subscription, {"id": f"p{k}", "type": "Customer", "distance": d,
                                                   "stamp": {"sec": stamp // 1000, "nanosec": 500_000_000}})
            assert report is not None
        api_gateway.store.flush(30)
        yield distances
    finally:
        api_gateway.settings.ros.subscriptions.remove(subscription)


def live_state(client, api_gateway) -> dict:
    api_gateway.store.flush(30)
    db = api_gateway.store.db
    return {"ruleset": client.get(f"/api/rulesets/{RULESET}").json()["version"],
            "query": client.get("/api/queries/ReplayNear").json()["version"],
            "decisions": db["decisions"].count_documents({}), "outcomes": db["actions"].count_documents({}),
            "messages": db["rdf_events"].count_documents({})}


def test_a_candidate_query_changes_exactly_the_windows_it_should(client, api_gateway, recorded):
    distances = recorded
    before = live_state(client, api_gateway)
    r = client.post("/api/streams/replay", json={**PERIOD, "queries": [{"query": query(3.0)}]})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["source"] == "rdf_events" and body["replayed"] == N and body["not_replayable"] == 0
    assert body["candidate"]["queries"] == ["ReplayNear"]
    assert body["detections"] == {"before": sum(d < 3.3 for d in distances), "after": sum(d < 3.0 for d in distances),
                                  "changed": sum(3.0 <= d < 3.3 for d in distances)}
    assert body["decisions"]["changed"] == body["detections"]["changed"] == body["changed"] > 0
    counts = {r["rule"]: (r["before"], r["after"]) for r in body["rules"]}
    assert counts["Greet"] == (sum(d < 2.0 for d in distances),) * 2
    assert counts["Wave"] == (sum(2.0 <= d < 3.3 for d in distances), sum(2.0 <= d < 3.0 for d in distances))
    change = body["changes"][0]
    k = next(i for i, d in enumerate(distances) if 3.0 <= d < 3.3)
    assert change["query"] == "ReplayNear" and change["window"] == {"start": T0 + k * 1000, "end": T0 + (k + 1) * 1000}
    assert change["before"]["fired"] == ["Wave"] and change["after"] == {"rows": None, "fired": None, "actions": None}
    assert change["before"]["rows"] == [{"person": f"{P}p{k}", "d": distances[k]}]
    assert live_state(client, api_gateway) == before  # nothing recorded, nothing live moved


def test_a_candidate_rule_set_changes_decisions_not_detections(client, api_gateway, recorded):
    distances = recorded
    before = live_state(client, api_gateway)
    body = client.post("/api/streams/replay", json={**PERIOD, "rulesets": {RULESET: {"files": rules(2.5)}}}).json()
    assert body["detections"]["changed"] == 0
    assert body["decisions"]["changed"] == sum(2.0 <= d < 2.5 for d in distances) == body["changed"]
    assert "hash" in body["candidate"]["rulesets"][RULESET]
    assert all(c["before"]["fired"] == ["Wave"] and c["after"]["fired"] == ["Greet"] for c in body["changes"])
    assert live_state(client, api_gateway) == before
    # the live text as the candidate changes nothing
    same = client.post("/api/streams/replay", json={**PERIOD, "rulesets": {RULESET: {"version": 1}},
                                                    "queries": [{"query": query(3.3)}]}).json()
    assert same["changed"] == 0 and same["decisions"]["before"] == sum(d < 3.3 for d in distances)


def test_a_candidate_mapping_replays_the_raw_messages(client, recorded):
    distances = recorded
    spec = {"subject": "printeps:guest_{id}", "fields": {"distance": "printeps:distance"}}
    body = client.post("/api/streams/replay", json={**PERIOD, "mappings": {MAPPING: {"spec": spec}},
                                                    "max_changes": 2}).json()
    assert body["source"] == "sensor_messages" and body["replayed"] == N
    detected = sum(d < 3.3 for d in distances)
    assert body["detections"] == {"before": detected, "after": detected, "changed": detected}
    assert len(body["changes"]) == 2 and body["changes_truncated"] is True
    assert body["changes"][0]["after"]["rows"][0]["person"].startswith(f"{P}guest_p")


def test_the_async_job_gives_the_same_answer(client, recorded):
    request = {**PERIOD, "queries": [{"query": query(3.0)}]}
    sync = client.post("/api/streams/replay", json=request).json()
    r = client.post("/api/streams/replay", json=request, headers=ASYNC)
    assert r.status_code == 202 and r.json()["kind"] == "replay"
    job = follow(client, r.headers["location"])
    assert job["status"] == "succeeded", job
    assert job["result"]["changes"] == sync["changes"] and job["result"]["detections"] == sync["detections"]


def test_bad_input_is_named(client, recorded):
    def post(**extra):
        return client.post("/api/streams/replay", json={**PERIOD, **extra})

    broken = post(queries=[{"query": query(3.0).replace("FILTER(", "FILTER((")}])
    assert broken.status_code == 422 and broken.json()["field"] == "queries[0].query" and broken.json()["line"] > 0
    compile_error = post(rulesets={RULESET: {"files": {"near.drl": "rule oops when then end x"}}})
    assert compile_error.status_code == 422 and compile_error.json()["errors"][0]["file"] == "near.drl"
    assert post(rulesets={RULESET: {"version": 99}}).status_code == 404
    binding = post(queries=[{"query": query(3.0), "rules": {**BINDING, "fact_type": "Nobody"}}])
    assert binding.status_code == 422 and "Nobody" in binding.json()["error"]
    assert post(limit=100_001).status_code == 422
    unused = post(mappings={"entrance-nope": {"spec": {"subject": "printeps:{id}"}}})
    assert unused.status_code == 422 and unused.json()["field"] == "mappings.entrance-nope"
    empty = client.post("/api/streams/replay", json={"since": iso(T0 - 10_000), "until": iso(T0 - 5_000),
                                                     "streams": [STREAM]})
    assert empty.status_code == 200 and empty.json()["replayed"] == 0 and "nothing was replayed" in empty.json()["note"]
    over = post(limit=10)
    assert over.json()["replayed"] == 10 and f"{N} recorded messages" in over.json()["note"]


def test_a_stateful_binding_is_replayed_for_its_detections_only_and_says_so(client, recorded):
    distances = recorded
    body = client.post("/api/streams/replay", json={**PERIOD, "queries": [
        {"query": query(3.3), "rules": {**BINDING, "mode": "stateful"}}]})
    assert body.status_code == 200, body.text
    body = body.json()
    assert [(b["query"], b["side"]) for b in body["not_replayable_bindings"]] == [("ReplayNear", "after")]
    assert "stateful" in body["not_replayable_bindings"][0]["reason"]
    detected = sum(d < 3.3 for d in distances)
    assert body["detections"] == {"before": detected, "after": detected, "changed": 0}
    assert body["decisions"] == {"before": detected, "after": 0, "changed": detected}
