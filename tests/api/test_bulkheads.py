"""Bulkheads, admission control and the fire time limit, over a real gateway (JVM + Drools, the
MongoDB-protocol server) served by a real uvicorn server.

The slow rule set's one rule waits in its then-part until the test creates a gate file, and
creates a "started" file first: so a test knows (by a condition, not a sleep) that a fire is
running, and decides when it ends.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from api_helpers import FACTS, ServerThread, files, make_settings
from gw_testing import GATED_JOB_DRL, Gate, built_gateway, wait_for
from gateway.api.main import create_app

SLOW = "slowset"
FAST = "quickset"
KIE = "/kie-server/services/rest/server/containers/instances"

SLOW_DRL = "package org.printeps.slowtest;\n\n" + GATED_JOB_DRL

LOOP_DRL = """package org.printeps.looptest;

declare Counter
    id : String
    n : int
end

declare Seen
    id : String
end

rule "Count for ever, slowly"
when
    $c : Counter( n < 1000000 )
then
    try { Thread.sleep(2); } catch (InterruptedException e) { }
    modify($c) { setN($c.getN() + 1) };
end
"""


@pytest.fixture(scope="module")
def rule_sets(client) -> None:
    assert client.put(f"/api/rulesets/{SLOW}", json={"files": {"slow.drl": SLOW_DRL}}).status_code == 201
    assert client.put(f"/api/rulesets/{FAST}", json={"files": files("bh")}).status_code == 201


def _serve(api_gateway, api_settings, **api: Any) -> ServerThread:
    return ServerThread(create_app(api_gateway, api_settings.api.model_copy(update=api))).start()


def _in_background(fn: Any) -> tuple[threading.Thread, list[Any]]:
    """Runs ``fn`` in a thread; its answer (or the exception it raised) ends up in the list."""
    out: list[Any] = []

    def run() -> None:
        try:
            out.append(fn())
        except Exception as exc:  # shown by the assertion that reads ``out``
            out.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    return thread, out


def _fire(url: str, name: str, facts: list[dict[str, Any]], timeout: float = 60.0) -> httpx.Response:
    return httpx.post(f"{url}/api/rulesets/{name}/fire", json={"facts": facts}, timeout=timeout)


def test_a_slow_rule_set_does_not_hold_up_another_or_health(api_gateway, api_settings, rule_sets, tmp_path):
    # max_wait_s: the queued slow fire must still be served after the test's 20 fast fires, however
    # busy the machine (at the default 5 s it was refused with 503 at load 30)
    server = _serve(api_gateway, api_settings, fire_workers=1, max_wait_s=120)
    gates = [Gate(tmp_path, f"slow{k}") for k in range(2)]
    try:
        bulkheads = server.server.config.app.state.bulkheads
        slow = [_in_background(lambda: _fire(server.url, SLOW, gates[0].facts()))]
        assert wait_for(gates[0].started.exists, 60), f"the slow fire never started: {slow[0][1]}"
        slow.append(_in_background(lambda: _fire(server.url, SLOW, gates[1].facts())))
        assert wait_for(lambda: bulkheads.stats()[SLOW]["waiting"] == 1, 60), bulkheads.stats()
        # the slow set's one thread is blocked, its second fire waits in its queue: the others go on
        worst = 0.0
        with httpx.Client(base_url=server.url, timeout=30) as c:
            for _ in range(20):
                t0 = time.perf_counter()
                assert c.post(f"/api/rulesets/{FAST}/fire", json={"facts": FACTS}).status_code == 200
                assert c.get("/health").status_code in (200, 503)  # answered; the store may be busy
                worst = max(worst, time.perf_counter() - t0)
        assert worst < 5.0, f"a fast fire and /health took {worst:.2f} s beside a blocked rule set"
        assert not gates[1].started.exists()  # the slow set's share is one thread: the second still waits
        stats = bulkheads.stats()[SLOW]
        assert stats["running"] == 1 and stats["waiting"] == 1
        for gate in gates:
            gate.open()
        for thread, out in slow:
            thread.join(60)
            assert out and out[0].status_code == 200, out
    finally:
        for gate in gates:
            gate.open()
        server.stop()


def test_a_full_queue_is_refused_at_once_with_429_and_counted(api_gateway, api_settings, rule_sets, tmp_path):
    server = _serve(api_gateway, api_settings, fire_workers=1, max_queue=2, max_wait_s=60)
    gates = [Gate(tmp_path, f"q{k}") for k in range(3)]
    bulkheads = server.server.config.app.state.bulkheads
    try:
        running = [_in_background(lambda g=g: _fire(server.url, SLOW, g.facts())) for g in gates]
        assert wait_for(lambda: bulkheads.stats().get(SLOW, {}).get("waiting") == 2, 60), bulkheads.stats()
        t0 = time.perf_counter()
        refused = _fire(server.url, SLOW, Gate(tmp_path, "extra").facts())
        assert time.perf_counter() - t0 < 5.0  # at once, not after the queue
        assert refused.status_code == 429, refused.text
        assert int(refused.headers["Retry-After"]) >= 1
        body = refused.json()
        assert body["kind"] == "overloaded" and body["reason"] == "queue_full"
        assert body["ruleset"] == SLOW and body["limit"] == 2 and body["setting"] == "api.max_queue"
        assert SLOW in body["error"] and "api.max_queue" in body["error"]
        kie = httpx.post(f"{server.url}{KIE}/{SLOW}", timeout=30, json={"commands": [
            {"insert": {"object": {"org.printeps.slowtest.Job": {"id": "k", "started": "-", "gate": "-"}}}}]})
        assert kie.status_code == 429 and kie.json()["type"] == "FAILURE", kie.text
        assert int(kie.headers["Retry-After"]) >= 1 and "api.max_queue" in kie.json()["msg"]
        # the fast rule set has a queue of its own
        assert _fire(server.url, FAST, FACTS, timeout=30).status_code == 200
        metrics = httpx.get(f"{server.url}/metrics").text
        assert f'printeps_fires_refused_total{{reason="queue_full",ruleset="{SLOW}"}} 2.0' in metrics
        # the queue-depth gauge: two waiting (the limit), one running; the fast set's queue is empty
        assert f'printeps_fire_queue_depth{{ruleset="{SLOW}"}} 2.0' in metrics
        assert f'printeps_fires_running{{ruleset="{SLOW}"}} 1.0' in metrics
        assert f'printeps_fire_queue_depth{{ruleset="{FAST}"}} 0.0' in metrics
        assert "printeps_fire_queue_limit 2.0" in metrics
        for gate in gates:
            gate.open()
        for thread, out in running:
            thread.join(60)
            assert out and out[0].status_code == 200, out
        drained = httpx.get(f"{server.url}/metrics").text
        assert f'printeps_fire_queue_depth{{ruleset="{SLOW}"}} 0.0' in drained
        assert f'printeps_fires_running{{ruleset="{SLOW}"}} 0.0' in drained
    finally:
        for gate in gates:
            gate.open()
        server.stop()


def test_a_fire_that_waited_too_long_is_refused_with_503(api_gateway, api_settings, rule_sets, tmp_path):
    server = _serve(api_gateway, api_settings, fire_workers=1, max_queue=8, max_wait_s=0.5)
    first, second = Gate(tmp_path, "w1"), Gate(tmp_path, "w2")
    try:
        blocking = _in_background(lambda: _fire(server.url, SLOW, first.facts()))
        assert wait_for(first.started.exists, 60)
        late = _in_background(lambda: _fire(server.url, SLOW, second.facts()))
        # queued on the server (not only sent: on a busy machine the request may take a while to get
        # there, and a fire queued less than 0.5 s before its turn runs), then past api.max_wait_s
        bulkheads = server.server.config.app.state.bulkheads
        assert wait_for(lambda: bulkheads.stats().get(SLOW, {}).get("waiting") == 1, 60), bulkheads.stats()
        queued_at = time.monotonic()
        assert wait_for(lambda: time.monotonic() - queued_at > 1.0, 5)
        first.open()
        for thread, _ in (blocking, late):
            thread.join(60)
        assert blocking[1][0].status_code == 200
        answer = late[1][0]
        assert answer.status_code == 503, answer.text
        assert answer.json()["kind"] == "overloaded" and answer.json()["setting"] == "api.max_wait_s"
        assert int(answer.headers["Retry-After"]) >= 1
        assert not second.started.exists()  # refused before it fired: nothing of it ran
        # the set's mean fire time is now over a second: the next fire behind a running one would wait
        # longer than 0.5 s, so it is refused at once instead of queueing
        third = Gate(tmp_path, "w3")
        blocking = _in_background(lambda: _fire(server.url, SLOW, third.facts()))
        assert wait_for(third.started.exists, 60)
        t0 = time.perf_counter()
        at_once = _fire(server.url, SLOW, Gate(tmp_path, "w4").facts())
        assert at_once.status_code == 503 and time.perf_counter() - t0 < 5.0, at_once.text
        third.open()
        blocking[0].join(60)
        metrics = httpx.get(f"{server.url}/metrics").text
        assert f'printeps_fires_refused_total{{reason="waited",ruleset="{SLOW}"}} 2.0' in metrics
    finally:
        for gate in (first, second):
            gate.open()
        server.stop()


# ---- the fire time limit --------------------------------------------------------------------------


@pytest.fixture(scope="module")
def limited(mongo, tmp_path_factory) -> Iterator[Any]:
    """A gateway whose fires stop after half a second, with the looping rule set deployed."""
    from fastapi.testclient import TestClient

    settings = make_settings(tmp_path_factory.mktemp("timeout"))
    settings = settings.model_copy(update={"engine": settings.engine.model_copy(update={"fire_timeout_s": 0.5})})
    with built_gateway(settings, mongo, tmp_path_factory.mktemp("timeout-store")) as gateway:
        with TestClient(gateway.app) as client:
            files_ = {"loop.drl": LOOP_DRL,
                      "kmodule.xml": '<kmodule xmlns="http://www.drools.org/xsd/kmodule"><kbase name="k" default="true">'
                                     '<ksession name="counting" type="stateful" default="true"/></kbase></kmodule>'}
            assert client.put("/api/rulesets/looping", json={"files": files_}).status_code == 201, "deploy"
            yield gateway, client


def _decisions(gateway: Any, client: Any) -> list[dict[str, Any]]:
    gateway.store.flush()
    return client.get("/api/decisions", params={"ruleset": "looping"}).json()["decisions"]


def test_a_fire_past_its_time_limit_is_halted_with_503_and_not_recorded(limited):
    gateway, client = limited
    before = _decisions(gateway, client)
    t0 = time.perf_counter()
    r = client.post("/api/rulesets/looping/fire", json={"facts": [{"type": "Counter", "id": "c", "n": 0}]})
    elapsed = time.perf_counter() - t0
    assert r.status_code == 503, r.text
    body = r.json()
    assert body["kind"] == "timeout" and body["ruleset"] == "looping"
    assert body["limit"] == 0.5 and body["setting"] == "engine.fire_timeout_s"
    assert elapsed < 20.0  # 10,000 firings of 2 ms each (the runaway guard) would take 20 s and more
    assert _decisions(gateway, client) == before  # nothing recorded as fired
    assert "printeps_fire_timeouts_total" in client.get("/metrics").text
    # the rule set still answers a fire that ends in time
    assert client.post("/api/rulesets/looping/fire", json={"facts": [{"type": "Counter", "id": "d", "n": 999999}]}
                       ).status_code == 200


def test_a_kie_batch_past_its_time_limit_answers_failure_503(limited):
    gateway, client = limited
    before = _decisions(gateway, client)
    r = client.post(f"{KIE}/looping", json={"commands": [
        {"insert": {"object": {"org.printeps.looptest.Counter": {"id": "k", "n": 0}}}},
        {"fire-all-rules": {}}]})
    assert r.status_code == 503 and r.json()["type"] == "FAILURE", r.text
    assert "engine.fire_timeout_s" in r.json()["msg"]
    assert _decisions(gateway, client) == before


def test_a_stateful_session_after_a_timeout_is_as_before_the_halted_batch(limited):
    """A durable stateful session is rolled back (docs/rest-api.md, "Overload and time limits"):
    rebuilt from its log without the halted batch, it holds neither the batch's inserts nor what
    its firings changed, and still serves; no decision."""
    gateway, client = limited
    path = f"{KIE}/looping"
    # a fresh session (a batch without a lookup, above, may have gone to this default one)
    assert client.post(path, json={"lookup": "counting", "commands": [{"dispose": ""}]}).status_code == 200
    first = client.post(path, json={"lookup": "counting", "commands": [
        {"insert": {"object": {"org.printeps.looptest.Seen": {"id": "before"}}}}, {"fire-all-rules": {}}]})
    assert first.status_code == 200, first.text
    before = _decisions(gateway, client)
    halted = client.post(path, json={"lookup": "counting", "commands": [
        {"insert": {"object": {"org.printeps.looptest.Counter": {"id": "k", "n": 0}}}}, {"fire-all-rules": {}}]})
    assert halted.status_code == 503 and halted.json()["type"] == "FAILURE", halted.text
    assert _decisions(gateway, client) == before  # the halted batch is not a decision
    objects = client.post(path, json={"lookup": "counting", "commands": [{"get-objects": {"out-identifier": "all"}}]})
    assert objects.status_code == 200, objects.text
    values = {x["key"]: x["value"] for x in objects.json()["result"]["execution-results"]["results"]}
    kept = {next(iter(o)).rsplit(".", 1)[1]: next(iter(o.values())) for o in values["all"]}
    assert kept["Seen"]["id"] == "before"
    assert "Counter" not in kept  # the halted batch's insert (and its counting) was undone
    assert "rolled back" in halted.json()["msg"]
    client.post(path, json={"lookup": "counting", "commands": [{"dispose": ""}]})
