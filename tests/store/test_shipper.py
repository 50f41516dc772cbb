"""The shipper process (gateway.store.shipper): it inserts what the journal hands it, and a shipper
that dies, hangs or is interrupted costs a retry, never a write. Real SecantusDB, real processes."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from gw_testing import wait_for

from gateway.store.embedded import EmbeddedMongo
from gateway.store.shipper import ShipperFailed, ShipperProcess
from gateway.store.store import InformationState
from gateway.store.journal import encode


@pytest.fixture
def shipping(mongo: EmbeddedMongo, tmp_path: Path, request: pytest.FixtureRequest):
    s = InformationState(mongo.uri, f"t_{request.node.name[:40]}", tmp_path / "journal", timeout_ms=500,
                         retry_interval_s=0.1, ship_process=True)
    yield s
    s.close()


def _record(store: InformationState, first: int, n: int) -> None:
    for i in range(first, first + n):
        store.record("actions", {"n": i}, stored_type="printeps/Action")


def test_writes_go_in_through_the_shipper_process(shipping: InformationState) -> None:
    _record(shipping, 0, 50)
    assert shipping.flush(10)
    assert sorted(d["n"] for d in shipping.query("actions", limit=100)) == list(range(50))
    assert shipping.shipper.started == 1 and shipping.shipper._proc.poll() is None


def test_a_killed_shipper_costs_a_retry_not_a_write(shipping: InformationState) -> None:
    _record(shipping, 0, 10)
    assert shipping.flush(10)
    shipping.shipper._proc.kill()
    shipping.shipper._proc.wait()
    _record(shipping, 10, 10)
    assert shipping.flush(15), shipping.health()
    assert sorted(d["n"] for d in shipping.query("actions", limit=100)) == list(range(20))
    assert shipping.shipper.started == 2 and shipping.health()["status"] == "ok"


def test_a_hung_shipper_is_replaced(shipping: InformationState) -> None:
    _record(shipping, 0, 5)
    assert shipping.flush(10)
    usual_timeout_s, shipping.shipper.answer_timeout_s = shipping.shipper.answer_timeout_s, 1.0
    hung = shipping.shipper._proc
    os.kill(hung.pid, signal.SIGSTOP)
    try:
        _record(shipping, 5, 5)
        assert wait_for(lambda: shipping.health()["status"] == "degraded", 10)
        assert "no answer" in shipping.health()["last_error"]
        # the replacement's cold start (a Python process, pymongo) is not held to the hung one's 1 s:
        # with the other xdist worker busy it took longer, and each new shipper was killed in turn
        shipping.shipper.answer_timeout_s = usual_timeout_s
        assert shipping.flush(15), shipping.health()
        assert shipping.shipper.started >= 2  # the hung process was replaced, not waited out
    finally:
        if hung.poll() is None:
            os.kill(hung.pid, signal.SIGCONT)
    assert hung.poll() is not None  # killed (and reaped), not left behind
    assert sorted(d["n"] for d in shipping.query("actions", limit=100)) == list(range(10))
    assert shipping.health()["status"] == "ok"


def test_the_shipper_outlives_ctrl_c_and_sigterm_until_its_parent_is_done(shipping: InformationState) -> None:
    _record(shipping, 0, 3)
    assert shipping.flush(10)
    child = shipping.shipper._proc
    child.send_signal(signal.SIGINT)
    child.send_signal(signal.SIGTERM)
    _record(shipping, 3, 3)
    assert shipping.flush(10)
    assert shipping.shipper.started == 1 and child.poll() is None
    shipping.close()
    assert child.wait(timeout=5) == 0  # its input ended: it exits by itself


def test_a_database_away_fails_the_batch_and_keeps_the_process(tmp_path: Path) -> None:
    shipper = ShipperProcess("mongodb://127.0.0.1:1/?directConnection=true", 200)
    try:
        with pytest.raises(ShipperFailed, match="ServerSelectionTimeoutError"):
            shipper.ship("db", "c", [encode("db", "c", {"_id": "0" * 24})], create_index=False)
        assert shipper._proc.poll() is None and shipper.started == 1
    finally:
        shipper.close()


PARENT = """
import sys, time
from gateway.store.store import InformationState
s = InformationState(sys.argv[1], "t_orphan", sys.argv[2], timeout_ms=500, ship_process=True)
s.record("actions", {"n": 1}, stored_type="printeps/Action")
assert s.flush(10)
print(s.shipper._proc.pid, flush=True)
time.sleep(600)
"""


def test_the_shipper_ends_when_its_parent_is_killed(mongo: EmbeddedMongo, tmp_path: Path) -> None:
    parent = subprocess.Popen([sys.executable, "-c", PARENT, mongo.uri, str(tmp_path / "journal")],
                              stdout=subprocess.PIPE, text=True)
    try:
        child = int(parent.stdout.readline())
    finally:
        parent.send_signal(signal.SIGKILL)
        parent.wait(timeout=10)

    def gone() -> bool:
        try:
            with open(f"/proc/{child}/stat") as fh:
                return fh.read().split(")")[-1].split()[0] == "Z"  # a zombie until init reaps it
        except FileNotFoundError:
            return True

    assert wait_for(gone, 10)
