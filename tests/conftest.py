"""Shared test set-up: every test process gets one real JVM (started on first use) and one real
MongoDB-protocol server; gateways are built through the one composition root."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from gw_testing import open_test_store

# Under CI=true a skip is a failure unless tests/skip_allowlist.txt lists it (tests/ci_skips.py).
from ci_skips import (  # noqa: F401
    pytest_collectreport, pytest_runtest_makereport, pytest_sessionfinish, pytest_terminal_summary)

# Keep the test runs' caches (compiled Java helpers) in one place across runs.
os.environ.setdefault("PRINTEPS_CACHE_DIR", os.path.expanduser("~/.cache/printeps"))
# Gateways the tests start as processes (printeps serve, the cluster) build no explain queries in
# advance: each would spend seconds of a core per rule set it loads (tests/gw_testing.py does the
# same for the gateways built in-process; the tests of the prebuild turn it on).
os.environ.setdefault("PRINTEPS_EXPLAIN_PREBUILD", "0")


CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
    "--disable-sync", "--no-first-run", "--disable-quic",
]


@pytest.fixture(scope="session")
def browser():
    """One headless Debian chromium for the whole run: Playwright's sync API allows only one
    running instance per thread, so every browser test shares this one."""
    if not os.path.exists(CHROMIUM):
        pytest.skip(f"{CHROMIUM} is missing: apt-get install -y chromium")
    from playwright.sync_api import expect, sync_playwright

    # expect()'s wait is a safety limit, not a speed claim: 5 s (Playwright's default) is missed on a
    # loaded 2-core machine by a first check that has to warm the JVM up.
    expect.set_options(timeout=20_000)
    with sync_playwright() as playwright:
        launched = playwright.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        yield launched
        launched.close()


# ---- the Information State: one real MongoDB-protocol server (SecantusDB, its own process) for
# the whole run; each test or module gets a database of its own on it (tests that stop and start
# the server, tests/store, start their own).

@pytest.fixture(scope="session")
def mongo(tmp_path_factory: pytest.TempPathFactory):
    from gateway.store.embedded import EmbeddedMongo

    db = EmbeddedMongo(tmp_path_factory.mktemp("mongo"))
    db.start()
    yield db
    db.stop()


@pytest.fixture
def store(mongo, tmp_path: Path):
    s = open_test_store(mongo, tmp_path)
    yield s
    s.close()
