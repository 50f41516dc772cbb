"""Fixtures of the REST gateway tests: one real gateway (JVM + Drools + Information State), built
through the one composition root, per test session; apps over it."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from gateway.config import Settings

from api_helpers import TOKENS, ServerThread, make_settings
from gw_testing import built_gateway


@pytest.fixture(scope="session")
def api_settings(tmp_path_factory: pytest.TempPathFactory) -> Settings:
    return make_settings(tmp_path_factory.mktemp("api"))


@pytest.fixture(scope="session")
def api_gateway(api_settings: Settings, mongo, tmp_path_factory: pytest.TempPathFactory):
    with built_gateway(api_settings, mongo, tmp_path_factory.mktemp("api-store")) as gateway:
        yield gateway


@pytest.fixture(scope="session")
def engine(api_gateway):
    return api_gateway.engine


@pytest.fixture(scope="session")
def client(api_gateway) -> Iterator[TestClient]:
    with TestClient(api_gateway.app) as c:
        yield c


@pytest.fixture(scope="session")
def secured(api_settings: Settings, api_gateway) -> Iterator[TestClient]:
    """An app with auth on, over the same gateway."""
    from gateway.api.main import create_app

    api = api_settings.api.model_validate({"tokens": TOKENS, "basic_users": "kieserver:kiepw:caller"})
    with TestClient(create_app(api_gateway, api)) as c:
        yield c


@pytest.fixture(scope="session")
def live_server(api_gateway) -> Iterator[ServerThread]:
    server = ServerThread(api_gateway.app).start()
    yield server
    server.stop()
