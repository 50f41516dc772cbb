"""Fixtures of the workbench tests: the real gateway (JVM + Drools engine + REST API + workbench
router) served by uvicorn on 127.0.0.1, and Debian's chromium driven by Playwright.

One server and one browser per test session (starting them is the slow part); each test gets a
fresh browser context (own localStorage) and, where it changes rules, its own rule set, deployed
through the REST API from a copy of ``rules/drl/reception``, so tests do not depend on each other.
"""

from __future__ import annotations

import itertools
import os
import shutil
import socket
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from gateway.config import PROJECT_ROOT, Settings

from gw_testing import built_gateway
from wb_helpers import AUTHOR_TOKEN, CALLER_TOKEN, RECEPTION, TOKENS, new_page, reception_files  # noqa: F401

START_TIMEOUT_S = 60

_names = itertools.count(1)


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


class Gateway:
    """A running gateway: its base URL, its engine, and REST helpers that act as a given token."""

    def __init__(self, base_url: str, engine) -> None:
        self.base_url = base_url
        self.engine = engine

    def rest(self, token: str = AUTHOR_TOKEN) -> httpx.Client:
        return httpx.Client(base_url=self.base_url, headers={"Authorization": f"Bearer {token}"}, timeout=30)

    def deploy(self, name: str, files: dict[str, str], comment: str, base_version: int | None = None,
               token: str = AUTHOR_TOKEN) -> httpx.Response:
        with self.rest(token) as client:
            return client.put(f"/api/rulesets/{name}",
                              json={"files": files, "comment": comment, "base_version": base_version})

    def fire(self, name: str, facts: list[dict]) -> dict:
        with self.rest(CALLER_TOKEN) as client:
            response = client.post(f"/api/rulesets/{name}/fire", json={"facts": facts})
            response.raise_for_status()
            return response.json()


@pytest.fixture(scope="session")
def gateway(tmp_path_factory: pytest.TempPathFactory, mongo) -> Iterator[Gateway]:
    """The gateway as `printeps serve` builds it (no ROS), seeded with a copy of the reception rules
    and of the dialogue rules (the take_order workflow's ask_order step converses through them)."""
    from gateway.serve import serve_in_thread

    root = tmp_path_factory.mktemp("workbench")
    shutil.copytree(RECEPTION, root / "rules" / "reception")
    shutil.copytree(PROJECT_ROOT / "rules" / "drl" / "dialogue", root / "rules" / "dialogue")
    settings = Settings.model_validate({
        "data_dir": str(root / "var"),
        "engine": {"rules_dir": str(root / "rules")},
        "api": {"tokens": TOKENS},
    })
    with built_gateway(settings, mongo, root) as gw:
        server, thread = serve_in_thread(gw.app, _free_port(), name="workbench-gateway", timeout_s=START_TIMEOUT_S)
        yield Gateway(f"http://127.0.0.1:{server.config.port}", gw.engine)
        server.should_exit = True
        thread.join(timeout=10)
    thread.join(timeout=10)


@pytest.fixture()
def ruleset(gateway: Gateway) -> str:
    """A fresh copy of the reception rule set (version 1) under a name of its own."""
    name = f"teahouse-{os.getpid()}-{next(_names)}"
    response = gateway.deploy(name, reception_files(), "copy of reception for a test")
    assert response.status_code == 201, response.text
    return name


@pytest.fixture()
def author_page(browser, gateway: Gateway):
    page = new_page(browser, gateway, AUTHOR_TOKEN)
    yield page
    page.context.close()
    assert page.js_errors == []


@pytest.fixture()
def screenshots(tmp_path: Path) -> Path:
    """Where screenshots go: docs/img when PRINTEPS_SCREENSHOTS=1 (to refresh the docs), else tmp."""
    if os.environ.get("PRINTEPS_SCREENSHOTS") == "1":
        target = PROJECT_ROOT / "docs" / "img"
        target.mkdir(parents=True, exist_ok=True)
        return target
    return tmp_path
