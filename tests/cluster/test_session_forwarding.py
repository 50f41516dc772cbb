"""Stateful sessions across real gateway processes over one MongoDB-protocol server: a session
lives in the process that created it (recorded in the Information State), calls that reach
another process are forwarded to it, a gone owner of a session that is not durable answers 410; with ``--workers`` each worker's
private loopback port carries the forwarded calls, so a conversation on the shared port is
continuous whichever worker takes each call."""

from __future__ import annotations

import signal
import time

import httpx
import pytest
from test_processes import Process, cluster_home, stop_all, wait_for

pytestmark = pytest.mark.slow
BASE = "/kie-server/services/rest/server"
PKG = "org.printeps.cluster"


@pytest.fixture(scope="module")
def home(tmp_path_factory, mongo):
    # not durable: this file pins the 410 of a lost session (durable ones: test_durable_takeover.py)
    return cluster_home(tmp_path_factory, mongo, "sessions", {"sessions": {"member_heartbeat_s": 1.0, "durable": False}})


def insert(url: str, cid: str, lookup: str = "defaultKieSession") -> httpx.Response:
    return httpx.post(f"{url}{BASE}/containers/instances/cluster", timeout=30, json={"lookup": lookup, "commands": [
        {"insert": {"object": {f"{PKG}.Customer": {"id": cid, "age": 30}}, "out-identifier": cid}},
        {"fire-all-rules": {"out-identifier": "fired"}},
        {"get-objects": {"out-identifier": "all"}}]})


def ids(r: httpx.Response) -> list[str]:
    assert r.status_code == 200, r.text
    results = {x["key"]: x["value"] for x in r.json()["result"]["execution-results"]["results"]}
    return sorted(o[f"{PKG}.Customer"]["id"] for o in results["all"])


def test_forwarding_between_two_processes_and_410_when_the_owner_is_gone(home):
    folder, config, env = home
    a, b = Process("SA", config, env, folder).start(), Process("SB", config, env, folder).start()
    try:
        a.ready()
        b.ready()
        # the KIE session is created on A; B forwards to it: one conversation, one set of facts
        assert ids(insert(a.url, "from-a")) == ["from-a"]
        via_b = insert(b.url, "from-b")
        assert ids(via_b) == ["from-a", "from-b"]
        assert via_b.headers["x-session-owner"].endswith(f":{a.proc.pid}")
        # a REST session made on B is reached through A, by handle
        made = httpx.post(f"{b.url}/api/rulesets/cluster/sessions", json={"facts": [{"type": "Customer", "id": "r1", "age": 5}]})
        assert made.status_code == 201, made.text
        sid, handle = made.json()["id"], made.json()["handles"][0]
        assert made.json()["process"].endswith(f":{b.proc.pid}")
        facts = httpx.get(f"{a.url}/api/rulesets/cluster/sessions/{sid}/facts").json()["facts"]
        assert [(f["handle"], f["fact"]["id"]) for f in facts] == [(handle, "r1")]
        fired = httpx.post(f"{a.url}/api/rulesets/cluster/sessions/{sid}/fire").json()
        assert [x["params"]["text"] for x in fired["actions"]] == ["Hello r1"]
        listed = httpx.get(f"{a.url}/api/rulesets/cluster/sessions").json()["sessions"]
        owners = {s["id"]: s["process"] for s in listed}
        assert owners["defaultKieSession"].endswith(f":{a.proc.pid}") and owners[sid].endswith(f":{b.proc.pid}")
        # B dies: its session (and facts) are gone, and A says so
        b.proc.send_signal(signal.SIGKILL)
        b.proc.wait(timeout=30)
        gone = httpx.get(f"{a.url}/api/rulesets/cluster/sessions/{sid}/facts")
        assert gone.status_code == 410, gone.text
        assert "gone" in gone.json()["error"] and "facts are lost" in gone.json()["error"]
        # the KIE session lives on A: a new B (another process) still reaches it
        b2 = Process("SB2", config, env, folder).start().ready()
        try:
            assert ids(insert(b2.url, "from-b2")) == ["from-a", "from-b", "from-b2"]
            # A dies: the next KIE call on B2 is told the session is gone, the one after starts afresh
            a.proc.send_signal(signal.SIGKILL)
            a.proc.wait(timeout=30)
            lost = insert(b2.url, "x")
            assert lost.status_code == 410 and lost.json()["type"] == "FAILURE" and "is gone" in lost.json()["msg"]
            assert ids(insert(b2.url, "fresh")) == ["fresh"]
        finally:
            b2.stop()
    finally:
        stop_all(a, b)


def workers_registered(served: Process) -> list[dict]:
    """The member records of ``served``'s worker processes (children of its master process)."""
    from pymongo import MongoClient

    def parent(pid: int) -> int | None:
        try:
            status = open(f"/proc/{pid}/status").read()
        except OSError:
            return None
        return int(status.split("PPid:")[1].split()[0])

    with MongoClient(served.env["MONGO_URI"]) as client:
        members = list(client["sessions"]["members"].find())
    return [m for m in members if parent(int(m.get("pid", 0))) == served.proc.pid]


def test_workers_keep_one_conversation_on_the_shared_port(home):
    folder, config, env = home
    served = Process("SW", config, env, folder, "--workers", "2").start()
    try:
        served.ready()
        # both workers have announced their private address (a worker not yet registered could
        # neither own a session nor be forwarded to)
        assert wait_for(lambda: len(workers_registered(served)) == 2, 120), workers_registered(served)
        session = httpx.post(f"{served.url}/api/rulesets/cluster/sessions", json={}).json()["id"]
        owners = set()
        for k in range(30):  # new connections: the kernel spreads them over both workers
            with httpx.Client(timeout=30) as c:
                r = c.post(f"{served.url}/api/rulesets/cluster/sessions/{session}/facts",
                           json={"facts": [{"type": "Customer", "id": f"w{k}", "age": 1}]})
                assert r.status_code == 201, r.text
                assert r.json()["fact_count"] == k + 1
                owners.add(r.headers.get("x-session-owner", "here"))
        assert len(owners) == 2  # some calls were answered by the owner itself, some forwarded to it
        # the conversation holds every fact, whichever worker is asked
        for _ in range(4):
            with httpx.Client(timeout=30) as c:
                listed = c.get(f"{served.url}/api/rulesets/cluster/sessions").json()["sessions"]
                assert [x["id"] for x in listed if x["id"] == session] == [session], listed
        assert httpx.get(f"{served.url}/health", timeout=30).status_code == 200
    finally:
        served.stop()
