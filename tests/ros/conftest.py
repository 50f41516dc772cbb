"""Fixtures for the ROS tests: real rclpy nodes over loopback, each test on its own ROS_DOMAIN_ID;
the real SecantusDB and JVM are the session's (tests/conftest.py)."""

from __future__ import annotations

import itertools
import os
from pathlib import Path

import pytest

from gateway.config import Settings

# No folder-wide skip: test_core.py is plain Python and runs everywhere. The modules that need rclpy
# skip on their own without it (and under CI=true a skip is a failure, tests/conftest.py).

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


def _domain_band() -> tuple[int, int]:
    """(first domain, how many) this process may use: 1..100 (0..101 are safe on Linux), split
    between the pytest-xdist workers of `make test` so two workers never share a domain."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    worker = int(os.environ.get("PYTEST_XDIST_WORKER", "gw0").removeprefix("gw") or 0)
    size = 100 // max(workers, 1)
    return 1 + worker * size, size


_first, _size = _domain_band()
# the process id picks the start inside the band: other test runs on the same host use others
_domains = itertools.count(os.getpid() % _size)


@pytest.fixture
def domain_id() -> int:
    """A ROS domain of its own per test, inside this worker's band."""
    return _first + next(_domains) % _size


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    s = Settings(data_dir=str(tmp_path / "var"))
    s.ros.call_timeout_s = 1.0
    s.ros.call_retries = 1
    return s
