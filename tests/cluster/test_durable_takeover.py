"""Durable sessions across real gateway processes over one MongoDB-protocol server and one data
dir (issue 28): a session outlives the process that held it. Its owner SIGKILLed while another
process feeds it, every acknowledged insert is there afterwards; the next call anywhere takes it
over (one winner among racing processes) with the same facts, handles, clock and version; a lone
``printeps serve`` restarted on its data dir serves its sessions again; a KIE ``lookup`` reaches
the taken-over ksession; a session that followed a deploy is rebuilt on the version it followed;
a corrupt snapshot falls back to the log."""

from __future__ import annotations

import os
import signal
import threading
import time
from pathlib import Path

import httpx
import pytest
from test_processes import Process, cluster_home, files, stop_all, wait_for

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
        stop_all(a, b)



def shipper_of(p: Process) -> int:
    """The pid of ``p``'s shipper process (gateway.store.shipper: it inserts what p journals)."""
    assert p.proc is not None

    def find() -> int | None:
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                ppid = int(stat.read_text().rsplit(")", 1)[1].split()[1])
                if ppid == p.proc.pid and b"gateway.store.shipper" in (stat.parent / "cmdline").read_bytes():
                    return int(stat.parent.name)
            except (OSError, ValueError, IndexError):
                continue
        return None

    assert wait_for(lambda: find() is not None, 60), f"no shipper process under {p.name}"
    pid = find()
    assert pid is not None
    return pid


def lock_holder(path: Path) -> int | None:
    """The pid holding the flock on ``path`` (from /proc/locks), None if nobody holds it."""
    try:
        inode = os.stat(path).st_ino
    except FileNotFoundError:
        return None
    for line in Path("/proc/locks").read_text().splitlines():
        parts = line.split()
        if len(parts) > 5 and parts[1] == "FLOCK" and parts[5].rsplit(":", 1)[-1] == str(inode):
            return int(parts[4])
    return None


def request_waiting_at(port: int) -> bool:
    """Whether a connection to ``port`` has bytes its (stopped) server has not read yet."""
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        for line in Path(table).read_text().splitlines()[1:]:
            parts = line.split()
            if int(parts[1].rsplit(":", 1)[1], 16) == port and int(parts[4].split(":")[1], 16) > 0:
                return True
    return False


def test_owner_gone_mid_forward_while_a_third_process_ships_its_journal_keeps_every_acknowledged_insert(home):
    """Issue 28 with three processes on one host, made deterministic with SIGSTOP. A owns a session
    B feeds (forwarded to A); A's last acknowledged inserts are only in A's local journal (its
    shipper process is stopped). B's next insert is forwarded to A, which is frozen, and B is frozen
    too; A is then SIGKILLed, and C, taking over another of A's sessions, adopts A's journal and is
    still shipping it (its shipper stopped) when B wakes, finds its forward failed and A dead, and
    takes the session over through that failed forward. B must wait for C's shipping of A's journal:
    every acknowledged insert is there afterwards (B rebuilt without A's last 20 before)."""
    folder, config, env = home
    a, b, c = (Process(n, config, env, folder).start() for n in ("JA", "JB", "JC"))
    stopped: list[int] = []

    def stop(pid: int) -> None:
        os.kill(pid, signal.SIGSTOP)
        stopped.append(pid)

    def resume(pid: int) -> None:
        os.kill(pid, signal.SIGCONT)
        stopped.remove(pid)

    try:
        for p in (a, b, c):
            p.ready()
        made = httpx.post(f"{a.url}{API}", json={"facts": [{"type": "Customer", "id": "first", "age": 30}]}, timeout=60)
        assert made.status_code == 201, made.text
        sid = made.json()["id"]
        other = httpx.post(f"{a.url}{API}", json={"facts": [{"type": "Customer", "id": "other", "age": 30}]},
                           timeout=60).json()["id"]
        assert httpx.post(f"{c.url}/api/rulesets/cluster/fire", json={"facts": [{"type": "Customer", "id": "c", "age": 1}]},
                          timeout=60).status_code == 200  # a recorded decision: C's shipper process is started
        acked: list[str] = []

        def insert(k: int) -> None:
            r = call("POST", f"{b.url}{API}/{sid}/facts", json={"facts": [{"type": "Customer", "id": f"g{k}", "age": 1}]})
            assert r.status_code == 201, r.text
            acked.append(f"g{k}")

        for k in range(20):
            insert(k)
        a_pid, a_shipper, c_shipper = a.proc.pid, shipper_of(a), shipper_of(c)  # type: ignore[union-attr]
        stop(a_shipper)  # A journals and acknowledges, but ships nothing more
        for k in range(20, 40):
            insert(k)
        stop(c_shipper)
        stop(a_pid)
        b_takes = threading.Thread(target=insert, args=(40,))
        b_takes.start()
        assert wait_for(lambda: request_waiting_at(a.port), 60), "B did not forward to A"  # B found A alive
        stop(b.proc.pid)  # type: ignore[union-attr]
        stopped.remove(a_pid)
        kill(a)
        os.kill(a_shipper, signal.SIGKILL)  # orphaned and stopped: it would never read the end of its input
        stopped.remove(a_shipper)
        taken: dict[str, list[str]] = {}
        c_takes = threading.Thread(target=lambda: taken.setdefault("other", facts(c.url, other)))
        c_takes.start()  # C's takeover of the other session adopts A's journal now, and cannot ship it

        def c_holds_a_journal() -> bool:
            journal = folder / "var" / "store" / "journal"
            return any(lock_holder(f) == c.proc.pid for f in journal.glob(f"{a_pid}-*.jsonl*")  # type: ignore[union-attr]
                       if not f.name.endswith(".new"))

        assert wait_for(c_holds_a_journal, 60), "C did not adopt A's journal"
        resume(b.proc.pid)  # type: ignore[union-attr]  # its forward fails: B takes the session over
        wait_for(lambda: not b_takes.is_alive(), 3)  # it waits for C's shipping (before: it did not)
        resume(c_shipper)
        b_takes.join(timeout=120)
        c_takes.join(timeout=120)
        for k in range(41, 50):
            insert(k)
        assert acked == [f"g{k}" for k in range(50)]
        held = facts(b.url, sid)
        assert sorted(set(acked) - set(held)) == [] and "first" in held  # every acknowledged insert
        assert len(held) == 51
        assert taken["other"] == ["other"]
        assert rebuilt_in(b, c) == 2
    finally:
        for pid in stopped:
            os.kill(pid, signal.SIGCONT)
        stop_all(a, b, c)

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
        stop_all(a, b, c)


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
        stop_all(a, b)


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
        stop_all(a, b)


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
        stop_all(a, b)
