"""Fixtures of the dialogue tests: one real gateway (JVM + Drools + Information State) with the
shipped dialogue rule set and ontology, built through the one composition root."""

from __future__ import annotations

import shutil
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from gateway.config import Settings
from gw_testing import built_gateway

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def dialogue_settings(tmp_path_factory: pytest.TempPathFactory) -> Settings:
    tmp = tmp_path_factory.mktemp("dialogue")
    rules = tmp / "rules"
    shutil.copytree(ROOT / "rules" / "drl" / "dialogue", rules / "dialogue")
    return Settings.model_validate({"data_dir": str(tmp / "var"), "engine": {"rules_dir": str(rules)},
                                    "streams": {"queries_dir": None},
                                    "dialogue": {"watch_interval_s": 0.2}})


@pytest.fixture(scope="session")
def gateway(dialogue_settings: Settings, mongo, tmp_path_factory: pytest.TempPathFactory):
    with built_gateway(dialogue_settings, mongo, tmp_path_factory.mktemp("dialogue-store")) as gw:
        yield gw


@pytest.fixture(scope="session")
def client(gateway) -> Iterator[TestClient]:
    with TestClient(gateway.app) as c:
        yield c
