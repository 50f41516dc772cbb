"""The gateway node as its own process: starts, stops cleanly on SIGINT/SIGTERM, leaks no DDS files."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from gw_testing import short_lived_jvm

pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (ros/install.sh)")
pytest.importorskip("printeps_interfaces", reason="printeps_interfaces not built (ros/install.sh)")

pytestmark = pytest.mark.ros
ROOT = Path(__file__).resolve().parents[2]


def _shm() -> set[str]:
    return {p for p in os.listdir("/dev/shm") if "fastrtps" in p or "fast_datasharing" in p}


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_clean_shutdown(sig, domain_id, tmp_path) -> None:
    before = _shm()
    env = {**os.environ, "PRINTEPS_DATA_DIR": str(tmp_path), "ROS_DOMAIN_ID": str(domain_id),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    env.pop("MONGO_URI", None)
    proc = subprocess.Popen([sys.executable, "-m", "gateway.ros_launch"], cwd=ROOT, env=short_lived_jvm(env), text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    lines = []
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if "gateway node ready" in line:
                break
        assert any("gateway node ready" in x for x in lines), "".join(lines)
        proc.send_signal(sig)
        out, _ = proc.communicate(timeout=90)  # a safety limit: the node, the JVM and the database close in turn
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, "".join(lines) + out
    assert "gateway node stopping" in out
    assert _shm() - before == set()
    # the embedded database it started is gone too
    db_log = tmp_path / "mongo" / "secantusd.log"
    assert db_log.exists()
