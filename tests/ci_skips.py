"""Under ``CI=true`` every skipped test fails the run, unless tests/skip_allowlist.txt names it.

Why: a missing chromium, rclpy or node used to skip whole folders and CI still exited 0, so the
safety net could vanish without anyone seeing it. A skip that is truly expected (an optional
alternative, not something ``make test`` installs) goes on the allow-list with its reason; anything
else that skips in CI is a failure that names why it skipped and where the list is.

Loaded by tests/conftest.py (its hooks are re-exported there); the allow-list can be replaced
through ``PRINTEPS_SKIP_ALLOWLIST`` (the plugin's own tests use a list of their own).
"""

from __future__ import annotations

import os
from functools import cache
from pathlib import Path

import pytest

DEFAULT_ALLOWLIST = Path(__file__).with_name("skip_allowlist.txt")


def in_ci() -> bool:
    """True when the ``CI`` environment variable is set to anything but empty/0/false/no."""
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def allowlist_path() -> Path:
    return Path(os.environ.get("PRINTEPS_SKIP_ALLOWLIST") or DEFAULT_ALLOWLIST)


@cache
def allowed_skips(path: Path) -> dict[str, str]:
    """``{test id: reason}`` from the allow-list: one ``<test id>  # <reason>`` a line, ``#`` lines
    are comments. An entry without a reason is refused: the list exists to say why."""
    allowed: dict[str, str] = {}
    if not path.exists():
        return allowed
    for number, raw in enumerate(path.read_text().splitlines(), start=1):
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        test_id, _, reason = line.partition(" # ")
        if not reason.strip():
            raise pytest.UsageError(f"{path}:{number}: '{line}' has no reason (write '<test id>  # <why it may skip>')")
        allowed[test_id.strip()] = reason.strip()
    return allowed


def _is_allowed(nodeid: str) -> bool:
    """The test itself, or a parametrized test by its name without the parameters, is listed."""
    allowed = allowed_skips(allowlist_path())
    return nodeid in allowed or nodeid.split("[", 1)[0] in allowed


def _skip_reason(longrepr: object) -> str:
    if isinstance(longrepr, tuple) and len(longrepr) == 3:
        path, line, message = longrepr
        return f"{message} ({path}:{line})"
    return str(longrepr)


def _fail_message(nodeid: str, longrepr: object) -> str:
    return (f"{nodeid} was skipped under CI=true, and only the skips listed in {allowlist_path()} may be: "
            f"{_skip_reason(longrepr)}")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> object:
    """A skipped test (in setup, call or teardown) becomes a failure in CI unless allowed."""
    outcome = yield
    report = outcome.get_result()
    if in_ci() and report.skipped and not hasattr(report, "wasxfail") and not _is_allowed(item.nodeid):
        report.longrepr = _fail_message(item.nodeid, report.longrepr)
        report.outcome = "failed"


_skipped_collections: list[str] = []


def pytest_collectreport(report: pytest.CollectReport) -> None:
    """A module that skips as a whole (``importorskip`` at its top) is noted here and fails the run
    at its end (turning it into a collection error would interrupt every other test)."""
    if in_ci() and report.skipped and not _is_allowed(report.nodeid):
        _skipped_collections.append(_fail_message(report.nodeid, report.longrepr))


def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    if _skipped_collections and exitstatus == pytest.ExitCode.OK:
        session.exitstatus = pytest.ExitCode.TESTS_FAILED


def pytest_terminal_summary(terminalreporter: object, exitstatus: int, config: pytest.Config) -> None:
    """Says that skips are failures in CI, and names each module that skipped as a whole."""
    if not in_ci():
        return
    write = terminalreporter.write_line  # type: ignore[attr-defined]
    for message in _skipped_collections:
        write(f"FAILED (skipped module) {message}", red=True)
    write(f"CI=true: skips fail the run unless {allowlist_path()} lists them "
          f"({len(allowed_skips(allowlist_path()))} listed)")
