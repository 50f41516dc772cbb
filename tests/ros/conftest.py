"""Fixtures for the ROS tests: real rclpy nodes over loopback, each test on its own ROS_DOMAIN_ID,
a real SecantusDB (own process, pymongo only) and one real Drools engine per test session."""

from __future__ import annotations

import itertools
import os
from pathlib import Path

import pytest

pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (ros/install.sh)")
pytest.importorskip("printeps_interfaces", reason="printeps_interfaces not built (ros/install.sh)")

from gateway.config import Settings  # noqa: E402
from gateway.store.embedded import EmbeddedMongo  # noqa: E402
from gateway.store.store import InformationState  # noqa: E402

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
_domains = itertools.count(30 + os.getpid() % 40)


@pytest.fixture
def domain_id() -> int:
    """A ROS domain of its own per test (0..101 are safe on Linux)."""
    return 1 + next(_domains) % 100


@pytest.fixture(scope="session")
def mongo(tmp_path_factory: pytest.TempPathFactory):
    db = EmbeddedMongo(tmp_path_factory.mktemp("mongo"))
    db.start()
    yield db
    db.stop()


@pytest.fixture
def store(mongo: EmbeddedMongo, tmp_path: Path, request: pytest.FixtureRequest):
    name = "r_" + "".join(ch if ch.isalnum() else "_" for ch in request.node.name)[:40]
    s = InformationState(mongo.uri, name, tmp_path / "spool.jsonl", timeout_ms=500, retry_interval_s=0.2)
    yield s
    s.close()


@pytest.fixture(scope="session")
def engine_rules(tmp_path_factory: pytest.TempPathFactory):
    """The real engine with the repository's rule sets (JVM started once per session)."""
    from gateway.ros.stages import engine_stage

    settings = Settings(data_dir=str(tmp_path_factory.mktemp("engine")))
    engine, rules = engine_stage(settings)
    return rules


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    s = Settings(data_dir=str(tmp_path / "var"))
    s.ros.call_timeout_s = 1.0
    s.ros.call_retries = 1
    return s
