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
_domains = itertools.count(30 + os.getpid() % 40)


@pytest.fixture
def domain_id() -> int:
    """A ROS domain of its own per test (0..101 are safe on Linux)."""
    return 1 + next(_domains) % 100


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    s = Settings(data_dir=str(tmp_path / "var"))
    s.ros.call_timeout_s = 1.0
    s.ros.call_retries = 1
    return s
