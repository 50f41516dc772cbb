"""Shared test set-up: every test process gets one real JVM (started on first use) and one real
MongoDB-protocol server; gateways are built through the one composition root."""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

import pytest

import scheduling
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
# Nor do they warm the JIT up at start (engine.process_warm_up): two builds of a small rule set and
# fires of every live set, ~2 CPU-s a process, which its shutdown then waited for (4.4 s of a
# cluster process's 10 s stop). The tests of the warm-up call it themselves.
os.environ.setdefault("PRINTEPS_PROCESS_WARM_UP", "0")


#: Debian's chromium-headless-shell: the headless-only build Playwright itself uses for headless
#: runs. It has no browser UI to drive, so the same pages cost ~22% less chromium CPU (the
#: workbench tests: 254 -> 198 CPU-s, docs/operations.md). The full chromium serves where the
#: shell is not installed.
CHROMIUM = next((path for path in ("/usr/bin/chromium-headless-shell", "/usr/bin/chromium") if os.path.exists(path)),
                "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
    "--disable-sync", "--no-first-run", "--disable-quic",
    # fewer processes for the same pages (one origin, no GPU): ~9% less chromium CPU measured on
    # six workflow-editor tests (18.6 -> 16.9 CPU-s)
    "--in-process-gpu", "--disable-site-isolation-trials",
]


@pytest.fixture(scope="session")
def browser():
    """One headless Debian chromium for the whole run: Playwright's sync API allows only one
    running instance per thread, so every browser test shares this one."""
    if not os.path.exists(CHROMIUM):
        pytest.skip(f"{CHROMIUM} is missing: make browser (apt-get install -y chromium-headless-shell)")
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


TESTS = Path(__file__).resolve().parent
# The tests that use ROS 2 run as one unit on one xdist worker: tests/ros/test_process.py checks
# that no DDS shared-memory files (/dev/shm, machine-wide) are left behind, which another worker's
# ROS test would be creating meanwhile. Every test marked `ros` must be under one of these
# (checked at collection).
ROS_UNIT = ("ros", "workflow/test_ros.py", "sync/test_gateway_record.py", "demo/test_demo.py")


def _in_ros_unit(path: Path | str) -> bool:
    relative = Path(path).relative_to(TESTS) if Path(path).is_relative_to(TESTS) else Path(path)
    if relative.parts[:1] == (TESTS.name,):  # a node id: tests/ros/test_node.py
        relative = Path(*relative.parts[1:])
    return any(relative == Path(unit) or Path(unit) in relative.parents for unit in ROS_UNIT)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """On pytest-xdist workers (`make test`), the files come longest first by their measured time
    (tests/scheduling.py, tests/durations.json), the ROS unit as one. The order inside each file
    stays as written, and a run in one process keeps the usual order. Every worker collects the
    same list, as xdist needs."""
    if not os.environ.get("PYTEST_XDIST_WORKER"):
        return
    for item in items:
        if item.get_closest_marker("ros") and not _in_ros_unit(item.path):
            item.add_marker(pytest.mark.outside_ros_unit)
    files = [scheduling.file_of(item.nodeid) for item in items]
    seconds = scheduling.estimated_seconds(scheduling.load(), Counter(files))
    order = {file: rank for rank, file in enumerate(
        scheduling.longest_first(dict.fromkeys(files), seconds, _scope))}
    items.sort(key=lambda item: order[scheduling.file_of(item.nodeid)])


def _scope(file: str) -> str:
    """What one worker runs as a whole: a file, or all of ROS_UNIT."""
    return "ROS_UNIT" if _in_ros_unit(file) else file


def pytest_runtest_setup(item: pytest.Item) -> None:
    """A `ros` test outside ROS_UNIT fails, naming the list to add its file to."""
    if item.get_closest_marker("outside_ros_unit"):
        pytest.fail(f"{item.nodeid} is marked `ros` but its file is not in ROS_UNIT (tests/conftest.py): "
                    "under xdist it would run beside the other ROS tests", pytrace=False)


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--record-durations", action="store_true",
                     help="write each test file's measured time into tests/durations.json (make durations)")


def pytest_configure(config: pytest.Config) -> None:
    """``--record-durations``: the controlling process (it sees every worker's reports) records."""
    if config.getoption("record_durations") and not os.environ.get("PYTEST_XDIST_WORKER"):
        config.pluginmanager.register(scheduling.Recorder(), "record-durations")


def pytest_xdist_make_scheduler(config: pytest.Config, log: object) -> object | None:
    """`--dist loadfile`, except that the files of ROS_UNIT go to one worker as a whole."""
    if config.getoption("dist", None) != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    # The workers' collection is already longest first (pytest_collection_modifyitems above); xdist's
    # own reorder (by number of tests) would undo that.
    config.option.loadscopereorder = False

    class LoadFileAndFolderScheduling(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            scope = super()._split_scope(nodeid)
            return "ROS_UNIT" if _in_ros_unit(scope) else scope

    return LoadFileAndFolderScheduling(config, log)
