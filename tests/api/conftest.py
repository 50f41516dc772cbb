"""Fixtures of the REST gateway tests: one real engine (JVM + Drools) per test session, apps over it."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from gateway.config import Settings


def make_settings(tmp: Path, **api: object) -> Settings:
    rules_dir = tmp / "rules"
    rules_dir.mkdir(parents=True, exist_ok=True)
    return Settings.model_validate(
        {"data_dir": str(tmp / "var"), "engine": {"rules_dir": str(rules_dir)}, "api": api}
    )


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


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class ServerThread:
    """A real uvicorn server on 127.0.0.1 in a thread (stopped by ``stop``)."""

    def __init__(self, app, port: int | None = None) -> None:
        import uvicorn

        self.port = port or free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        config = uvicorn.Config(app, host="127.0.0.1", port=self.port, log_level="warning", access_log=False)
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, daemon=True)

    def start(self, timeout: float = 30.0) -> "ServerThread":
        self.thread.start()
        deadline = time.monotonic() + timeout
        while not self.server.started:
            if time.monotonic() > deadline or not self.thread.is_alive():
                raise RuntimeError("uvicorn did not start")
            time.sleep(0.02)
        return self

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(timeout=10)


@pytest.fixture(scope="session")
def live_server(api_settings: Settings, engine) -> Iterator[ServerThread]:
    from gateway.api.app import create_app

    server = ServerThread(create_app(api_settings, engine)).start()
    yield server
    server.stop()
