"""A stateful stream binding's session is a durable session (issue 28 item 4), with real processes:
a lone ``printeps serve`` fed sensor messages over REST keeps the binding's facts and clock when it
is stopped (SIGTERM) or killed (SIGKILL) and started again on the same data dir; the binding's
next window fires into the same session (what fired before stays fired); removing the binding
disposes it."""

from __future__ import annotations

import json
import signal
import threading
import time

import httpx
import pytest
from test_processes import Process, cluster_home, stop_all, wait_for

pytestmark = pytest.mark.slow
STREAM = "http://example.org/sensors"
SESSION = "/api/rulesets/sensors/sessions/stream.Readings"
DRL = """package org.printeps.sensors;
import org.printeps.gateway.Actions;
global Actions actions;
declare Reading
    id : String
    value : int
end
rule "Note a reading"
when
    $r : Reading()
then
    actions.say("pepper", "reading " + $r.getId());
end
"""
QUERY = """REGISTER QUERY Readings AS
PREFIX ex: <http://example.org/>
SELECT ?s ?value
FROM STREAM <http://example.org/sensors> [RANGE 1s STEP 1s]
WHERE { ?s ex:value ?value }"""
BINDING = {"ruleset": "sensors", "fact_type": "Reading", "fields": {"id": "s", "value": "value"}, "mode": "stateful"}


@pytest.fixture(scope="module")
def home(tmp_path_factory, mongo):
    return cluster_home(tmp_path_factory, mongo, "streamdurable", {"sessions": {"snapshot_every": 2}})


def call(method: str, url: str, **kwargs) -> httpx.Response:
    """A patient client: a 503 (the session is being rebuilt) is retried after its Retry-After."""
    deadline = time.monotonic() + 90
    while True:
        r = httpx.request(method, url, timeout=60, **kwargs)
        if r.status_code != 503 or time.monotonic() > deadline:
            return r
        time.sleep(min(float(r.headers.get("retry-after", "1")), 1.0))


def post(url: str, ts: int, reading: str | None = None) -> None:
    triples = [[f"<http://example.org/{reading}>", "<http://example.org/value>", ts]] if reading else []
    r = httpx.post(f"{url}/api/streams", json={"stream": STREAM, "timestamp": ts, "triples": triples}, timeout=60)
    assert r.status_code == 200, r.text


def readings(url: str) -> list[str] | None:
    """The binding's session's readings (None: no such session, not yet fired)."""
    r = call("GET", f"{url}{SESSION}/facts")
    if r.status_code == 404:
        return None
    assert r.status_code == 200, r.text
    return sorted(f["fact"]["id"] for f in r.json()["facts"])


def session(url: str) -> dict:
    r = call("GET", f"{url}{SESSION}")
    assert r.status_code == 200, r.text
    return r.json()


def fired(url: str) -> list[str]:
    """The texts said by the binding's decisions, oldest first."""
    r = httpx.get(f"{url}/api/decisions", params={"ruleset": "sensors", "origin": "stream", "limit": 100}, timeout=60)
    assert r.status_code == 200, r.text
    return sorted(str(a.get("params", {}).get("text")) for d in r.json()["decisions"] for a in d.get("actions", []))


def bind(url: str, query: str) -> None:
    """Deploys the sensors rule set on ``url`` and registers ``query`` with the stateful binding."""
    assert httpx.put(f"{url}/api/rulesets/sensors", json={"files": {"sensors.drl": DRL}},
                     timeout=180).status_code in (200, 201)
    r = httpx.post(f"{url}/api/queries", json={"query": query, "rules": BINDING}, timeout=60)
    assert r.status_code == 201, r.text


def test_a_stateful_binding_keeps_its_facts_and_clock_across_restarts(home):
    folder, config, env = home
    p = Process("SA", config, env, folder).start().ready()
    try:
        bind(p.url, QUERY)
        post(p.url, 500, "r1")
        post(p.url, 1500, "r2")  # closes the window ending at 1000: r1 fires
        post(p.url, 2500)  # closes the one ending at 2000: r2
        assert wait_for(lambda: readings(p.url) == ["r1", "r2"], 60) is not None
        before = session(p.url)
        assert before["durable"] is True and before["time"] == 2000, before

        p.stop()  # SIGTERM: the binding's session is put away, its log kept
        p = Process("SA2", config, env, folder).start().ready()
        assert readings(p.url) == ["r1", "r2"]  # rebuilt from its snapshot and log
        assert session(p.url)["time"] == 2000
        post(p.url, 3500, "r3")
        post(p.url, 4500)  # closes the window ending at 4000: r3 fires into the same session
        assert wait_for(lambda: readings(p.url) == ["r1", "r2", "r3"], 60) is not None

        p.proc.send_signal(signal.SIGKILL)  # type: ignore[union-attr]
        p.proc.wait(timeout=30)  # type: ignore[union-attr]
        p = Process("SA3", config, env, folder).start().ready()
        post(p.url, 5500, "r4")
        post(p.url, 6500)  # the binding's own next fire rebuilds the session here (no REST read first)
        assert wait_for(lambda: readings(p.url) == ["r1", "r2", "r3", "r4"], 60) is not None
        assert session(p.url)["time"] == 6000
        texts = ["reading r1", "reading r2", "reading r3", "reading r4"]
        assert wait_for(lambda: fired(p.url) == texts, 30) is not None, fired(p.url)  # none fired twice

        assert httpx.delete(f"{p.url}/api/queries/Readings/rules", timeout=60).status_code == 200
        assert wait_for(lambda: httpx.get(f"{p.url}{SESSION}", timeout=60).status_code == 404, 30) is not None
    finally:
        p.stop()


def test_a_window_firing_in_a_process_that_does_not_own_the_bindings_session_is_an_error_naming_the_owner(home):
    """A stateful binding fires in one process: the first whose window fires it owns its session.
    A window of the same binding in another process (its own stream messages) does not fire there,
    nor open a second session: it is reported as an ``error`` event (and the query's last_error)
    naming the owner, and the owner's session is left as it was."""
    folder, config, env = home
    query = QUERY.replace("Readings", "Owned")
    owned = SESSION.replace("Readings", "Owned")
    owner = Process("OA", config, env, folder).start().ready()
    other: Process | None = None
    try:
        bind(owner.url, query)
        post(owner.url, 500, "o1")
        post(owner.url, 1500)  # closes the window ending at 1000: o1 fires, and this process owns the session
        assert wait_for(lambda: call("GET", f"{owner.url}{owned}/facts").status_code == 200, 60) is not None
        owner_process = call("GET", f"{owner.url}{owned}").json()["process"]
        assert owner_process.endswith(f":{owner.proc.pid}")  # type: ignore[union-attr]

        other = Process("OB", config, env, folder).start().ready()  # loads the query and its binding
        assert httpx.get(f"{other.url}/api/queries/Owned", timeout=60).json()["binding"]["mode"] == "stateful"
        events: list[tuple[str, dict]] = []
        connected = threading.Event()

        def listen() -> None:
            with httpx.stream("GET", f"{other.url}/api/queries/Owned/live", timeout=90) as live:
                kind = None
                for line in live.iter_lines():
                    if line.startswith(": connected"):
                        connected.set()
                    elif line.startswith("event: "):
                        kind = line[len("event: "):]
                    elif line.startswith("data: ") and kind is not None:
                        events.append((kind, json.loads(line[len("data: "):])))
                        if kind == "error":
                            return

        listener = threading.Thread(target=listen, daemon=True)
        listener.start()
        assert wait_for(lambda: connected.is_set(), 30) is not None  # subscribed before the window closes
        post(other.url, 2500, "o2")
        post(other.url, 3500)  # closes the window ending at 3000 in the other process
        assert wait_for(lambda: any(k == "error" for k, _ in events), 60) is not None, events
        error = next(e for k, e in events if k == "error")["error"]
        assert f"held by gateway process {owner_process}" in error and "stream.Owned" in error, error
        info = httpx.get(f"{other.url}/api/queries/Owned", timeout=60).json()
        assert info["stats"]["rule_errors"] >= 1 and owner_process in info["last_error"]
        assert not any(k == "actions" for k, _ in events)  # nothing fired in the other process
        # the session stays the owner's, untouched: read through the other process, it is forwarded there
        assert call("GET", f"{other.url}{owned}").json()["process"] == owner_process
        assert sorted(f["fact"]["id"] for f in call("GET", f"{other.url}{owned}/facts").json()["facts"]) == ["o1"]
        assert httpx.delete(f"{owner.url}/api/queries/Owned/rules", timeout=60).status_code == 200
    finally:
        stop_all(owner, *([other] if other is not None else []))
