"""``GET /api/live``: the live feed of a real gateway (JVM + Drools + stream engine + Information
State, built by the one composition root with the shipped rules, queries and mappings) as
Server-Sent Events: entrance readings posted to the stream come back as ``reading`` events, the
CustomerDetectionQuery's results as ``detection``, the reception rules' fire as ``decision`` (whose
id opens the decision) and the robot actions as ``action`` with their outcome."""

from __future__ import annotations

import json
import threading
import time

import httpx
import pytest
from fastapi.testclient import TestClient

from gateway.config import Settings
from gateway.runtime.live import LiveFeed, distances_in

from api_helpers import ServerThread
from gw_testing import built_gateway

ENTRANCE = "http://printeps.org/cafe/entrance"
WAIT_S = 30


def approaching_party(t0_ms: int, ids: tuple[str, str]) -> list[dict]:
    """Entrance messages of two people walking up to the entrance, one per second."""
    return [{"stream": ENTRANCE, "timestamp": t0_ms + 1000 * i, "message": {
        "id": f"e{t0_ms}-{i}", "number_of_customers": 2, "customers": [
            {"id": ids[0], "distance": d, "age": 34, "gender": "female"},
            {"id": ids[1], "distance": d + 0.05, "age": 36, "gender": "female"}]}}
        for i, d in enumerate([5.0, 4.0, 3.0, 2.0, 1.8, 1.8])]


@pytest.fixture(scope="module")
def gateway(tmp_path_factory: pytest.TempPathFactory, mongo):
    """The gateway as ``printeps serve`` builds it (no ROS): the shipped reception rules, the
    CustomerDetectionQuery bound to them, the entrance mapping."""
    root = tmp_path_factory.mktemp("live")
    settings = Settings.model_validate({"data_dir": str(root / "var"),
                                        "workflows": {"simulate_robots": True, "simulate_humans": True}})
    with built_gateway(settings, mongo, root) as gw:
        yield gw


def wait_idle(gateway) -> None:
    """Until every queued robot action is performed (a condition, not a timing assertion)."""
    deadline = time.monotonic() + WAIT_S
    while not gateway.idle():
        assert time.monotonic() < deadline, "the gateway did not finish its actions"
        time.sleep(0.05)


def parse_sse(text: str) -> list[tuple[str, dict, str | None]]:
    """(event type, JSON data, id) of each event in an SSE body."""
    out = []
    for block in text.split("\n\n"):
        fields = dict(line.split(": ", 1) for line in block.splitlines() if ": " in line and not line.startswith(":"))
        if "event" in fields:
            out.append((fields["event"], json.loads(fields["data"]), fields.get("id")))
    return out


def test_distances_are_read_from_the_entrance_mapping_and_from_plain_triples(gateway) -> None:
    triples = gateway.mapper.map({"id": "e1", "number_of_customers": 2, "customers": [
        {"id": "a", "distance": 2.5, "age": 30, "gender": "male"},
        {"id": "b", "distance": 3, "age": 31, "gender": "female"}]}, 1000, "entrance")
    assert distances_in(triples) == {"a": 2.5, "b": 3.0}
    assert distances_in([]) == {}
    feed = LiveFeed()
    feed.on_stream_item("http://printeps.org/cafe/tables", 1000, triples)  # only the entrance is plotted
    feed.on_stream_item(ENTRANCE, 1000, triples)
    assert [(e["kind"], e["distances"]) for e in feed.recent()] == [("reading", {"a": 2.5, "b": 3.0})]


def test_replay_then_live_events_of_every_kind(gateway) -> None:
    client = TestClient(gateway.app)
    for message in approaching_party(10_000, ("p1", "p2")):
        assert client.post("/api/streams", json=message).status_code == 200
    wait_idle(gateway)
    kept = len(gateway.live.recent())
    response = client.get("/api/live", params={"max_events": kept})
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/event-stream")
    events = parse_sse(response.text)
    assert events[0][0] == "hello" and events[0][1]["feed"] == gateway.live.id
    by_kind: dict[str, list[dict]] = {}
    for kind, data, event_id in events[1:]:
        assert data["kind"] == kind and event_id == f"{gateway.live.id}-{data['seq']}"
        by_kind.setdefault(kind, []).append(data)
    assert set(by_kind) == {"reading", "detection", "decision", "action"}
    readings = by_kind["reading"]
    assert [r["t"] for r in readings] == [10_000 + 1000 * i for i in range(6)]
    assert readings[0]["distances"] == {"p1": 5.0, "p2": 5.05}
    detection = by_kind["detection"][0]
    assert detection["query"] == "CustomerDetectionQuery" and detection["solutions"] == 2
    decision = by_kind["decision"][0]
    assert decision["ruleset"] == "reception" and decision["origin"] == "stream" and decision["fired"]
    assert decision["query"] == "CustomerDetectionQuery"
    opened = client.get(f"/api/decisions/{decision['decision_id']}")
    assert opened.status_code == 200 and opened.json()["fired"] == decision["fired"]
    actions = [a for a in by_kind["action"] if a["decision_id"] == decision["decision_id"]]
    assert actions and all(a["status"] for a in actions)
    assert {a["module"] for a in actions} <= {a["module"] for a in decision["actions"]}
    # the order of the feed: a reading before what was detected in it, detected before decided
    seqs = {kind: [e["seq"] for e in items] for kind, items in by_kind.items()}
    assert seqs["reading"][0] < seqs["detection"][0] < seqs["decision"][0] < seqs["action"][0]


def test_a_connected_browser_gets_new_events_as_they_happen(gateway) -> None:
    server = ServerThread(gateway.app).start()
    received: list[tuple[str, dict]] = []
    try:
        subscribers = gateway.live.stats()["subscribers"]

        def listen() -> None:
            with httpx.Client(base_url=server.url, timeout=WAIT_S) as http, \
                    http.stream("GET", "/api/live", params={"replay": "false", "heartbeat_s": 1}) as r:
                kind = None
                for line in r.iter_lines():
                    if line.startswith("event: "):
                        kind = line[7:]
                    elif line.startswith("data: "):
                        received.append((kind, json.loads(line[6:])))
                        if kind == "decision":
                            return

        listener = threading.Thread(target=listen, daemon=True)
        listener.start()
        deadline = time.monotonic() + WAIT_S
        while gateway.live.stats()["subscribers"] <= subscribers:  # connected
            assert time.monotonic() < deadline
            time.sleep(0.02)
        with httpx.Client(base_url=server.url, timeout=WAIT_S) as http:
            for message in approaching_party(100_000, ("q1", "q2")):
                assert http.post("/api/streams", json=message).status_code == 200
        listener.join(timeout=WAIT_S)
        assert not listener.is_alive()
    finally:
        server.stop()
    kinds = [k for k, _ in received]
    assert kinds[0] == "hello" and "reading" in kinds and "detection" in kinds and kinds[-1] == "decision"
    # replay=false: nothing from before the connection
    assert all(d["t"] >= 100_000 for k, d in received if k == "reading")
    assert set(received[-1][1]["fired"])
    wait_idle(gateway)


def test_a_token_is_needed_when_tokens_are_configured(gateway) -> None:
    from gateway.api.main import create_app

    api = gateway.settings.api.model_validate({"tokens": "live-author:author:alice,live-caller:caller:bob"})
    with TestClient(create_app(gateway, api)) as client:
        refused = client.get("/api/live", params={"max_events": 1})
        assert refused.status_code == 401 and "Bearer" in refused.json()["error"]
        assert client.get("/api/live", params={"max_events": 1, "access_token": "wrong"}).status_code == 401
        by_query = client.get("/api/live", params={"max_events": 1, "access_token": "live-caller"})
        assert by_query.status_code == 200 and parse_sse(by_query.text)[0][1]["user"] == "bob"
        by_header = client.get("/api/live", params={"max_events": 1}, headers={"Authorization": "Bearer live-author"})
        assert by_header.status_code == 200 and parse_sse(by_header.text)[0][1]["user"] == "alice"


def test_a_slow_reader_loses_its_oldest_events_and_never_blocks() -> None:
    feed = LiveFeed(kept=3, queue_size=2)
    for i in range(5):
        feed.publish("reading", {"t": i, "distances": {"a": float(i)}})
    assert [e["t"] for e in feed.recent()] == [2, 3, 4]  # the last 3 kept for late joiners
    slow = feed.subscribe()
    for i in range(5, 9):
        feed.publish("decision", {"decision_id": str(i)})
    events, dropped = slow.take()
    assert [e.get("decision_id") for e in events] == ["7", "8"] and dropped == 5
    resumed = feed.subscribe(after=feed.recent()[-2]["seq"])
    assert [e.get("decision_id") for e in resumed.take()[0]] == ["8"]
    slow.close()
    resumed.close()
    assert feed.stats()["subscribers"] == 0


def test_resuming_from_last_event_id_sends_only_what_was_missed(gateway) -> None:
    client = TestClient(gateway.app)
    recent = gateway.live.recent()
    last = recent[-2]
    body = client.get("/api/live", params={"max_events": 1},
                      headers={"Last-Event-ID": f"{gateway.live.id}-{last['seq']}"}).text
    events = parse_sse(body)
    assert events[0][1]["resumed_after"] == last["seq"] and events[1][1]["seq"] == recent[-1]["seq"]


def test_closing_the_feed_ends_its_readers() -> None:
    feed = LiveFeed()
    woken: list[int] = []
    reader = feed.subscribe(lambda: woken.append(1))
    feed.close()
    assert reader.closed and woken and feed.stats()["subscribers"] == 0
    assert feed.subscribe().closed  # a server that is stopping takes no new reader for long
