"""Durable sessions across real gateway processes over one MongoDB-protocol server and one data
dir (issue 28): a session outlives the process that held it. Its owner SIGKILLed while another
process feeds it, every acknowledged insert is there afterwards; the next call anywhere takes it
over (one winner among racing processes) with the same facts, handles, clock and version; a lone
``printeps serve`` restarted on its data dir serves its sessions again; a KIE ``lookup`` reaches
the taken-over ksession; a session that followed a deploy is rebuilt on the version it followed;
a corrupt snapshot falls back to the log."""

from __future__ import annotations

import signal
import threading
import time

import httpx
import pytest
from test_processes import Process, cluster_home, files, wait_for

pytestmark = pytest.mark.slow
BASE = "/kie-server/services/rest/server"
PKG = "org.printeps.cluster"
API = "/api/rulesets/cluster/sessions"
SEEN = """package org.printeps.cluster;
import org.printeps.gateway.Actions;
global Actions actions;
rule "Seen"
when
    $c : Customer()
then
    actions.say("pepper", "Seen " + $c.getId());
end
"""


@pytest.fixture(scope="module")
def home(tmp_path_factory, mongo):
    return cluster_home(tmp_path_factory, mongo, "durable", {"sessions": {"member_heartbeat_s": 1.0, "snapshot_every": 5}})


def kill(p: Process) -> None:
    assert p.proc is not None
    p.proc.send_signal(signal.SIGKILL)
    p.proc.wait(timeout=30)


def call(method: str, url: str, **kwargs) -> httpx.Response:
    """One call as a patient client makes it: a 503 (being rebuilt, owner not yet known gone) is
    retried after its Retry-After; anything else is the answer."""
    deadline = time.monotonic() + 90
    while True:
        r = httpx.request(method, url, timeout=60, **kwargs)
        if r.status_code != 503 or time.monotonic() > deadline:
            return r
        assert "retry-after" in r.headers, r.text
        time.sleep(min(float(r.headers["retry-after"]), 1.0))


def facts(url: str, sid: str) -> list[str]:
    r = call("GET", f"{url}{API}/{sid}/facts")
    assert r.status_code == 200, r.text
    return sorted(f["fact"]["id"] for f in r.json()["facts"])


def said(r: httpx.Response) -> list[str]:
    assert r.status_code in (200, 201), r.text
    return sorted(a["params"]["text"] for a in r.json()["actions"])


def rebuilt_in(*processes: Process) -> int:
    return sum(p.output().count("rebuilt here") for p in processes)


def test_owner_killed_while_another_process_feeds_keeps_every_acknowledged_insert(home):
    folder, config, env = home
    a, b = Process("DA", config, env, folder).start(), Process("DB", config, env, folder).start()
    try:
        a.ready()
        b.ready()
        made = httpx.post(f"{a.url}{API}", json={"facts": [{"type": "Customer", "id": "first", "age": 30}]}, timeout=60)
        assert made.status_code == 201, made.text
        sid, handle = made.json()["id"], made.json()["handles"][0]
        assert said(httpx.post(f"{a.url}{API}/{sid}/fire", timeout=60)) == ["Hello first"]
        assert httpx.post(f"{a.url}{API}/{sid}/advance", json={"to": 7000}, timeout=60).json()["time"] == 7000
        acked: list[str] = []
        failures: list[str] = []

        def feed() -> None:  # through B, which forwards to the owner A (until A is gone)
            for k in range(120):
                r = call("POST", f"{b.url}{API}/{sid}/facts", json={"facts": [{"type": "Customer", "id": f"f{k}", "age": 1}]})
                (acked.append(f"f{k}") if r.status_code == 201 else failures.append(r.text))

        feeder = threading.Thread(target=feed)
        feeder.start()
        assert wait_for(lambda: len(acked) >= 40, 120)
        kill(a)
        feeder.join(timeout=300)
        assert not failures, failures[:3]
        assert len(acked) == 120
        held = facts(b.url, sid)
        assert set(acked) <= set(held) and "first" in held  # every acknowledged insert is there
        info = call("GET", f"{b.url}{API}/{sid}").json()
        assert info["process"].endswith(f":{b.proc.pid}") and info["time"] == 7000 and info["version"] == 1
        assert info["durable"] is True
        # the handle the client got from A still names its fact on B; what fired on A stays fired
        patched = call("PATCH", f"{b.url}{API}/{sid}/facts/{handle}", json={"set": {"age": 31}})
        assert patched.status_code == 200 and patched.json()["fact"]["id"] == "first", patched.text
        fired = said(call("POST", f"{b.url}{API}/{sid}/fire"))
        # the fed facts are greeted now, once each; "first" was greeted on A (and "Greet" does not
        # react to its age: property reactivity), so it stays greeted
        assert fired == sorted(f"Hello {x}" for x in held if x != "first")
        assert said(call("POST", f"{b.url}{API}/{sid}/fire")) == []
        assert rebuilt_in(a, b) == 1
    finally:
        a.stop()
        b.stop()


def test_two_processes_racing_to_take_over_one_wins_and_the_other_forwards(home):
    folder, config, env = home
    a, b, c = (Process(n, config, env, folder).start() for n in ("RA", "RB", "RC"))
    try:
        for p in (a, b, c):
            p.ready()
        sid = httpx.post(f"{a.url}{API}", json={"facts": [{"type": "Customer", "id": f"r{k}", "age": k} for k in range(50)]},
                         timeout=60).json()["id"]
        assert len(said(httpx.post(f"{a.url}{API}/{sid}/fire", timeout=60))) == 50
        kill(a)
        answers: dict[str, httpx.Response] = {}
        go = threading.Barrier(2)

        def take(p: Process) -> None:
            go.wait()
            answers[p.name] = call("POST", f"{p.url}{API}/{sid}/facts", json={"facts": [{"type": "Customer", "id": p.name, "age": 1}],
                                                                             "fire": True})

        racers = [threading.Thread(target=take, args=(p,)) for p in (b, c)]
        for t in racers:
            t.start()
        for t in racers:
            t.join(timeout=300)
        assert sorted(said(answers[n]) for n in ("RB", "RC")) == [["Hello RB"], ["Hello RC"]]
        assert rebuilt_in(b, c) == 1  # exactly one rebuilt it; the other forwarded to the winner
        owners = {call("GET", f"{p.url}{API}/{sid}").json()["process"] for p in (b, c)}
        assert len(owners) == 1
        assert facts(b.url, sid) == facts(c.url, sid) == sorted([f"r{k}" for k in range(50)] + ["RB", "RC"])
    finally:
        for p in (a, b, c):
            p.stop()


def test_a_lone_restart_serves_its_sessions_again(home):
    folder, config, env = home
    p = Process("LA", config, env, folder).start().ready()
    try:
        sid = httpx.post(f"{p.url}{API}", json={"id": "tea-table-4", "facts": [{"type": "Customer", "id": "t1", "age": 3}]},
                         timeout=60).json()["id"]
        assert said(httpx.post(f"{p.url}{API}/{sid}/fire", timeout=60)) == ["Hello t1"]
        handle = httpx.post(f"{p.url}{API}/{sid}/facts", json={"facts": [{"type": "Customer", "id": "t2", "age": 4}],
                                                              "timestamp": 90_000}, timeout=60).json()["handles"][0]
        p.stop()  # SIGTERM: a clean stop keeps durable sessions
        p = Process("LA2", config, env, folder).start().ready()
        assert facts(p.url, sid) == ["t1", "t2"]
        assert call("GET", f"{p.url}{API}/{sid}").json()["time"] == 90_000
        assert said(call("POST", f"{p.url}{API}/{sid}/fire")) == ["Hello t2"]  # t1 was greeted before the stop
        kill(p)  # and after a SIGKILL too
        p = Process("LA3", config, env, folder).start().ready()
        assert call("DELETE", f"{p.url}{API}/{sid}/facts/{handle}").json()["fact_count"] == 1
        assert call("DELETE", f"{p.url}{API}/{sid}").status_code == 200
        assert call("GET", f"{p.url}{API}/{sid}").status_code == 404  # disposed: gone for good
    finally:
        p.stop()


def kie(url: str, *commands: dict) -> httpx.Response:
    return call("POST", f"{url}{BASE}/containers/instances/cluster", json={"lookup": "defaultKieSession", "commands": [
        *commands, {"get-objects": {"out-identifier": "all"}}]})


def kie_ids(r: httpx.Response) -> list[str]:
    assert r.status_code == 200, r.text
    results = {x["key"]: x["value"] for x in r.json()["result"]["execution-results"]["results"]}
    return sorted(o[f"{PKG}.Customer"]["id"] for o in results["all"])


def test_kie_lookup_after_a_takeover_reaches_the_same_ksession(home):
    folder, config, env = home
    a, b = Process("KA", config, env, folder).start(), Process("KB", config, env, folder).start()
    try:
        a.ready()
        b.ready()
        for k in range(7):  # past a snapshot (sessions.snapshot_every: 5)
            ids = kie_ids(kie(a.url, {"insert": {"object": {f"{PKG}.Customer": {"id": f"k{k}", "age": k}}}},
                              {"fire-all-rules": {}}))
        assert ids == [f"k{k}" for k in range(7)]
        kill(a)
        after = kie(b.url, {"insert": {"object": {f"{PKG}.Customer": {"id": "kb", "age": 1}}}}, {"fire-all-rules": {}})
        assert kie_ids(after) == sorted([f"k{k}" for k in range(7)] + ["kb"])
        actions = next(x["value"] for x in after.json()["result"]["execution-results"]["results"] if x["key"] == "actions")
        assert [x["params"]["text"] for x in actions] == ["Hello kb"]  # the others fired on A, before it died
    finally:
        a.stop()
        b.stop()


def test_a_session_that_followed_a_deploy_is_rebuilt_on_that_version(home):
    folder, config, env = home
    a, b = Process("FA", config, env, folder).start(), Process("FB", config, env, folder).start()
    try:
        a.ready()
        b.ready()
        sid = httpx.post(f"{a.url}{API}", json={"facts": [{"type": "Customer", "id": "v", "age": 1}]}, timeout=60).json()["id"]
        assert said(httpx.post(f"{a.url}{API}/{sid}/fire", timeout=60)) == ["Hello v"]
        before = call("GET", f"{a.url}/api/rulesets/cluster").json()["version"]
        deployed = httpx.put(f"{a.url}/api/rulesets/cluster", json={"files": {**files("Hello"), "more.drl": SEEN}},
                             timeout=120)
        assert deployed.status_code == 201, deployed.text
        assert wait_for(lambda: call("GET", f"{a.url}{API}/{sid}").json()["version"] == before + 1, 60)
        kill(a)
        info = call("GET", f"{b.url}{API}/{sid}").json()
        assert info["version"] == before + 1 and info["process"].endswith(f":{b.proc.pid}")
        # "Greet" is unchanged: it does not fire again; the new rule fires once, for the fact that came across
        assert said(call("POST", f"{b.url}{API}/{sid}/fire")) == ["Seen v"]
        assert said(call("POST", f"{b.url}{API}/{sid}/fire")) == []
    finally:
        a.stop()
        b.stop()


def test_a_corrupt_snapshot_is_passed_over_for_the_one_before_and_the_log(home):
    from pymongo import MongoClient

    folder, config, env = home
    a, b = Process("CA", config, env, folder).start(), Process("CB", config, env, folder).start()
    try:
        a.ready()
        b.ready()
        sid = httpx.post(f"{a.url}{API}", json={}, timeout=60).json()["id"]
        for k in range(12):  # two snapshots (every 5 commands, after a fire)
            said(httpx.post(f"{a.url}{API}/{sid}/facts", json={"facts": [{"type": "Customer", "id": f"c{k}", "age": k}],
                                                                 "fire": True}, timeout=60))
        assert call("GET", f"{a.url}{API}/{sid}").json()["commands_since_snapshot"] == 2
        kill(a)
        with MongoClient(env["MONGO_URI"]) as client:
            snapshots = client["durable"]["session_snapshots"]
            assert wait_for(lambda: snapshots.count_documents({"key": {"$regex": f"^cluster/{sid}/"}}) == 2, 30)
            newest = snapshots.find_one({"key": {"$regex": f"^cluster/{sid}/"}}, sort=[("seq", -1)])
            assert newest["seq"] == 10
            snapshots.update_one({"_id": newest["_id"]}, {"$set": {"state": "{not json"}})
        assert facts(b.url, sid) == sorted(f"c{k}" for k in range(12))
        assert said(call("POST", f"{b.url}{API}/{sid}/fire")) == []
        assert "digest does not match" in b.output()
    finally:
        a.stop()
        b.stop()
