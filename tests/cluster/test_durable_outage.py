"""Durable sessions while the Information State is away (issue 28), with a real ``printeps serve``
and its own real MongoDB-protocol server (SecantusDB), stopped and started by the test: commands
are journalled locally and acknowledged, as decisions are, and everything ships once the database
is back (a process killed afterwards loses nothing); a journal at its bound refuses a command with
503 + ``Retry-After``, runs none of it, and takes it once the journal has drained."""

from __future__ import annotations

import httpx
import pytest
from test_processes import Process, cluster_home, wait_for

from gateway.store.embedded import EmbeddedMongo

pytestmark = pytest.mark.slow
API = "/api/rulesets/cluster/sessions"
SPOOL = 40  # store.spool_max_docs: small, so that an outage fills it in a few dozen commands


@pytest.fixture(scope="module")
def outage_db(tmp_path_factory):
    """A MongoDB-protocol server of this module's own: stopping it leaves the other tests' alone."""
    db = EmbeddedMongo(tmp_path_factory.mktemp("outage-mongo"))
    db.start()
    yield db
    db.stop()


@pytest.fixture(scope="module")
def home(tmp_path_factory, outage_db):
    return cluster_home(tmp_path_factory, outage_db, "outage", {
        "store": {"database": "outage", "spool_max_docs": SPOOL, "timeout_ms": 500, "retry_interval_s": 0.2}})


def health(p: Process) -> dict:
    return httpx.get(f"{p.url}/health", timeout=10).json()


def store_status(p: Process) -> str:
    return str(health(p)["store"].get("status"))


def insert(p: Process, sid: str, name: str) -> httpx.Response:
    return httpx.post(f"{p.url}{API}/{sid}/facts", json={"facts": [{"type": "Customer", "id": name, "age": 30}]}, timeout=60)


def ids(p: Process, sid: str) -> list[str]:
    r = httpx.get(f"{p.url}{API}/{sid}/facts", timeout=60)
    assert r.status_code == 200, r.text
    return sorted(f["fact"]["id"] for f in r.json()["facts"])


def shipped(p: Process) -> bool:
    """Everything journalled is in the database (the status may stay "degraded": it counts refusals)."""
    return health(p)["store"].get("buffered") == 0


def test_the_database_down_commands_are_journalled_and_acknowledged_then_shipped(home, outage_db):
    folder, config, env = home
    p = Process("OA", config, env, folder).start().ready()
    try:
        sid = httpx.post(f"{p.url}{API}", json={"id": "outage-1", "facts": [{"type": "Customer", "id": "before", "age": 30}]},
                         timeout=60).json()["id"]
        outage_db.stop()
        for k in range(10):
            r = insert(p, sid, f"down{k}")
            assert r.status_code == 201, r.text  # acknowledged: in the local journal
        fired = httpx.post(f"{p.url}{API}/{sid}/fire", timeout=60)
        assert fired.status_code == 200, fired.text
        assert len(fired.json()["actions"]) == 11
        assert wait_for(lambda: store_status(p) == "degraded", 30), health(p)
        assert health(p)["store"]["buffered"] >= 11  # none of it reached the database
        outage_db.start()
        assert wait_for(lambda: shipped(p), 60), health(p)
        p.signal(9)  # SIGKILL: only what reached the journal (and from it the database) is left
        p = Process("OA2", config, env, folder).start().ready()
        assert ids(p, sid) == sorted(["before"] + [f"down{k}" for k in range(10)])
        again = httpx.post(f"{p.url}{API}/{sid}/fire", timeout=60)
        assert again.status_code == 200 and again.json()["actions"] == []  # all were greeted before the kill
        assert httpx.delete(f"{p.url}{API}/{sid}", timeout=60).status_code == 200
    finally:
        p.stop()
        outage_db.start()  # (running already: nothing to do)


def test_a_full_journal_refuses_a_command_with_503_and_retry_after_and_runs_none_of_it(home, outage_db):
    folder, config, env = home
    p = Process("OB", config, env, folder).start().ready()
    try:
        sid = httpx.post(f"{p.url}{API}", json={"id": "outage-2"}, timeout=60).json()["id"]
        outage_db.stop()
        accepted, refused = [], None
        for k in range(SPOOL + 5):
            r = insert(p, sid, f"f{k}")
            if r.status_code != 201:
                refused = r
                break
            accepted.append(f"f{k}")
        assert refused is not None, "the journal never filled"
        assert refused.status_code == 503, refused.text
        assert refused.json()["kind"] == "journal" and "journal is full" in refused.json()["error"]
        assert int(refused.headers["retry-after"]) >= 1
        assert ids(p, sid) == sorted(accepted)  # the refused insert did not run
        outage_db.start()
        assert wait_for(lambda: shipped(p), 60), health(p)
        assert insert(p, sid, "after").status_code == 201  # the same command, sent again once the journal drained
        p.signal(9)
        p = Process("OB2", config, env, folder).start().ready()
        assert ids(p, sid) == sorted(accepted + ["after"])
        assert httpx.delete(f"{p.url}{API}/{sid}", timeout=60).status_code == 200
    finally:
        p.stop()
        outage_db.start()  # (running already: nothing to do)
