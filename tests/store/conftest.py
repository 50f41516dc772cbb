"""Fixtures: a real SecantusDB daemon (own process, pymongo only) per test module, in a temp dir."""

from __future__ import annotations

from pathlib import Path

import pytest

from gateway.config import Settings
from gateway.store.embedded import EmbeddedMongo
from gateway.store.store import InformationState


@pytest.fixture(scope="module")
def mongo(tmp_path_factory: pytest.TempPathFactory):
    db = EmbeddedMongo(tmp_path_factory.mktemp("mongo"))
    db.start()
    yield db
    db.stop()


@pytest.fixture(params=["thread", "process"])
def store(mongo: EmbeddedMongo, tmp_path: Path, request: pytest.FixtureRequest):
    """A store over the module's database, shipping its writes from a thread or from its shipper
    process (``store.ship_from``): every store test holds for both."""
    name = request.node.originalname[:40]  # one database per test and way of shipping
    s = InformationState(mongo.uri, f"t_{request.param[0]}_{name}",
                         tmp_path / "journal", backend="embedded", timeout_ms=500, retry_interval_s=0.2,
                         ship_process=request.param == "process")
    yield s
    s.close()


@pytest.fixture
def settings(tmp_path: Path) -> Settings:
    return Settings(data_dir=str(tmp_path / "var"))
