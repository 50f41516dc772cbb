"""Fixtures of the REST gateway tests: one real engine (JVM + Drools) per test session, apps over it."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from gateway.config import Settings

from api_helpers import ServerThread, make_settings


@pytest.fixture(scope="session")
def api_settings(tmp_path_factory: pytest.TempPathFactory) -> Settings:
    return make_settings(tmp_path_factory.mktemp("api"))


@pytest.fixture(scope="session")
def engine(api_settings: Settings):
    from gateway.engine import Engine

    return Engine(api_settings)


@pytest.fixture(scope="session")
def client(api_settings: Settings, engine) -> Iterator[TestClient]:
    from gateway.api.app import create_app

    with TestClient(create_app(api_settings, engine)) as c:
        yield c


TOKENS = "tok-author:author:alice,tok-caller:caller:bob"


@pytest.fixture(scope="session")
def secured(api_settings: Settings, engine) -> Iterator[TestClient]:
    """An app with auth on, over the same engine."""
    from gateway.api.app import create_app

    settings = api_settings.model_copy(
        update={"api": api_settings.api.model_validate({"tokens": TOKENS, "basic_users": "kieserver:kiepw:caller"})}
    )
    with TestClient(create_app(settings, engine)) as c:
        yield c


@pytest.fixture(scope="session")
def live_server(api_settings: Settings, engine) -> Iterator[ServerThread]:
    from gateway.api.app import create_app

    server = ServerThread(create_app(api_settings, engine)).start()
    yield server
    server.stop()
