"""REST: /api/queries, /api/streams, results, the live feed (SSE over a real loopback server)."""

from __future__ import annotations

import json
import socket
import threading
import time

import httpx
import pytest
import uvicorn
from fastapi.testclient import TestClient

from gateway.config import Settings

from csparql_scenarios import CUSTOMER_QUERY, ENTRANCE, approaching, messages
from gw_testing import built_gateway


@pytest.fixture()
def gateway(settings, mongo, tmp_path):
    full = Settings.model_validate({"data_dir": str(tmp_path / "var"), "engine": {"rules_dir": str(tmp_path / "rules")},
                                    "streams": settings.model_dump()})
    with built_gateway(full, mongo, tmp_path) as gw:
        yield gw


@pytest.fixture()
def client(gateway):
    return TestClient(gateway.app)


def _post_scenario(client, seconds=6):
    for ts, msg in messages({"c1": approaching(4.0, 0.3)}, hz=1, seconds=seconds, t0_ms=500):
        r = client.post("/api/streams", json={"stream": ENTRANCE, "timestamp": ts, "message": msg})
        assert r.status_code == 200, r.text


def test_register_list_results_delete(client):
    r = client.post("/api/queries", content=CUSTOMER_QUERY, headers={"content-type": "text/plain"})
    assert r.status_code == 201, r.text
    assert r.json()["name"] == "CustomerDetectionQuery" and r.json()["fast_path"] is True
    assert [q["name"] for q in client.get("/api/queries").json()["queries"]] == ["CustomerDetectionQuery"]
    assert client.post("/api/queries", json={"query": CUSTOMER_QUERY}).status_code == 409
    _post_scenario(client)
    results = client.get("/api/queries/CustomerDetectionQuery/results").json()["results"]
    # every evaluated window is listed, those without a detection too (rows [])
    assert [r["window"]["end"] for r in results] == [1000, 2000, 3000, 4000, 5000]
    detected = [r for r in results if r["rows"]]
    assert [r["window"]["end"] for r in detected] == [4000, 5000]
    assert detected[0]["rows"] == [{"s": "http://printeps.org/cafe/entrance/c1", "cnt": 3, "distance": 3.2}]
    assert client.delete("/api/queries/CustomerDetectionQuery").status_code == 204
    assert client.get("/api/queries/CustomerDetectionQuery").status_code == 404
    assert client.delete("/api/queries/CustomerDetectionQuery").status_code == 404


def test_parse_errors_are_422_with_line_and_column(client):
    bad = CUSTOMER_QUERY.replace("[RANGE 3s STEP 1s]", "[RANGE 1s STEP 3s]")
    r = client.post("/api/queries", json={"query": bad})
    assert r.status_code == 422
    body = r.json()
    assert "STEP" in body["error"] and body["line"] == 13 and body["column"] == 59
    r = client.post("/api/queries", json={"query": CUSTOMER_QUERY.replace("rdf:type", "rdfx:type")})
    assert r.status_code == 422 and r.json()["line"] == 15 and "rdfx" in r.json()["error"]
    r = client.post("/api/queries", content=b'{"query": ', headers={"content-type": "application/json"})
    assert r.status_code == 400 and r.json()["column"] == 11  # malformed JSON: 400, as everywhere in the API


def test_params_and_triples_over_rest(client):
    body = CUSTOMER_QUERY[CUSTOMER_QUERY.index("REGISTER"):]
    r = client.post("/api/queries", json={"query": body, "params": {"distance_to_entrance": {"value": 3.5}}})
    assert r.status_code == 201 and r.json()["param_values"] == {"distance_to_entrance": "3.5"}
    p = "printeps:"
    for i, (ts, d) in enumerate([(500, 3.9), (1500, 3.6), (2500, 3.3), (3500, 3.0)]):
        triples = [[p + "c1", "rdf:type", p + "Customer"], [p + "c1", p + "positionAtTime", f"{p}r{i}"],
                   [f"{p}r{i}", p + "distance", d]]
        assert client.post("/api/streams", json={"stream": ENTRANCE, "timestamp": ts, "triples": triples}).status_code == 200
    results = [r for r in client.get("/api/queries/CustomerDetectionQuery/results").json()["results"] if r["rows"]]
    assert results[0]["window"]["end"] == 3000 and results[0]["rows"][0]["distance"] == 3.4  # (3.6+3.3+3.3)/3


@pytest.mark.parametrize("body, status, where", [
    ({"stream": ENTRANCE, "timestamp": 1, "triples": [["printeps:a", "rdf:type"]]}, 422, "triples[0]"),
    ({"stream": ENTRANCE, "timestamp": 1, "triples": [["printeps:a", "bad:type", 1]]}, 422, "triples[0][1]"),
    ({"stream": ENTRANCE, "timestamp": -5, "triples": []}, 422, "timestamp"),
    ({"stream": "entrance", "timestamp": 1, "triples": []}, 422, "stream"),
    ({"stream": ENTRANCE, "timestamp": 1}, 422, "body"),
    ({"stream": ENTRANCE, "timestamp": 1, "message": {"id": "e", "customers": [{"distance": 1}]}}, 422,
     "message.customers[0].id"),
    ([{"stream": ENTRANCE, "timestamp": 1, "triples": []}, {"stream": ENTRANCE, "timestamp": "x", "triples": []}],
     422, "[1].timestamp"),
])
def test_bad_stream_input_is_refused_with_the_place(client, body, status, where):
    r = client.post("/api/streams", json=body)
    assert r.status_code == status and r.json()["where"] == where, r.text


def test_saturation_answers_503(client, gateway):
    pending, limit = gateway.app.state.stream_posts, gateway.settings.streams.max_pending_posts
    for _ in range(limit):
        pending.acquire()
    try:
        r = client.post("/api/streams", json={"stream": ENTRANCE, "timestamp": 1, "triples": []})
        assert r.status_code == 503 and r.json()["rejected_total"] == 1
    finally:
        for _ in range(limit):
            pending.release()
    assert client.get("/api/streams").json()["rejected_posts"] == 1


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_live_feed_over_sse(gateway):
    app = gateway.app
    port = _free_port()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 10
        while not server.started:
            assert time.monotonic() < deadline, "server did not start"
            time.sleep(0.05)
        with httpx.Client(base_url=base, timeout=10) as http:
            assert http.post("/api/queries", json={"query": CUSTOMER_QUERY}).status_code == 201
            received: list[dict] = []

            def listen() -> None:
                with http.stream("GET", "/api/queries/CustomerDetectionQuery/live?max_events=5") as r:
                    for line in r.iter_lines():
                        if line.startswith("data: "):
                            received.append(json.loads(line[6:]))

            listener = threading.Thread(target=listen, daemon=True)
            listener.start()
            while len(gateway.streams._subscribers) < 2:  # the feed is subscribed (besides the results recorder)
                assert time.monotonic() < deadline
                time.sleep(0.02)
            with httpx.Client(base_url=base, timeout=10) as poster:
                for ts, msg in messages({"c1": approaching(4.0, 0.3)}, hz=1, seconds=6, t0_ms=500):
                    poster.post("/api/streams", json={"stream": ENTRANCE, "timestamp": ts, "message": msg})
            listener.join(timeout=10)
            assert not listener.is_alive()
            # every window is published, empty ones included
            assert [e["window"]["end"] for e in received] == [1000, 2000, 3000, 4000, 5000]
            assert [e["window"]["end"] for e in received if e["rows"]] == [4000, 5000]
            assert all(e["kind"] == "result" for e in received)
    finally:
        server.should_exit = True
        thread.join(timeout=10)
