"""The order in which pytest-xdist hands test files to its workers: the longest first, by measured
time (tests/durations.json).

Why: `--dist loadfile` gives a worker a whole file at a time, and the run ends when the last
worker's last file does. Handing out the longest files first (the classic longest-processing-time
rule) leaves only short files for the end, so the workers finish together. xdist's own order
(``--loadscope-reorder``, the number of tests in a file) put one-test browser stories of 30–50 s
last and left the other workers idle for them (docs/operations.md, "Where the suite's time goes").

The times are what a whole run measured: ``make durations`` (``pytest --record-durations``) writes
them. A file the record does not know yet is estimated from its number of tests at the recorded
average, so a new file is neither first nor last by accident.
"""

from __future__ import annotations

import json
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path

TESTS = Path(__file__).resolve().parent
DURATIONS = TESTS / "durations.json"


def load(path: Path = DURATIONS) -> dict[str, dict[str, float]]:
    """The recorded times: ``{file: {"seconds": s, "tests": n}}``, files relative to the project
    (``tests/api/test_rest.py``); empty when there is no record."""
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}


def file_of(nodeid: str) -> str:
    """The test file of a node id, as the record names it (``tests/api/test_rest.py``)."""
    return nodeid.split("::", 1)[0]


def estimated_seconds(record: dict[str, dict[str, float]], tests_by_file: Counter[str]) -> dict[str, float]:
    """Each collected file's expected time: its recorded time, in proportion where fewer of its
    tests run (``-m "not slow"``, ``-k``), or its tests at the record's average a test."""
    recorded_tests = sum(entry["tests"] for entry in record.values())
    average = sum(entry["seconds"] for entry in record.values()) / recorded_tests if recorded_tests else 1.0
    expected = {}
    for file, count in tests_by_file.items():
        entry = record.get(file)
        expected[file] = (entry["seconds"] * min(1.0, count / entry["tests"]) if entry and entry["tests"]
                          else count * average)
    return expected


def longest_first(files: Iterable[str], seconds: dict[str, float], scope: Callable[[str], str]) -> list[str]:
    """``files`` ordered by the expected time of their scope (a file, or a unit of files one worker
    runs together), longest first; a unit's files stay together, ties keep the given order."""
    files = list(files)
    by_scope: dict[str, float] = {}
    for file in files:
        by_scope[scope(file)] = by_scope.get(scope(file), 0.0) + seconds.get(file, 0.0)
    first_seen = {scope_name: i for i, scope_name in reversed(list(enumerate(map(scope, files))))}
    return sorted(files, key=lambda file: (-by_scope[scope(file)], first_seen[scope(file)]))


class Recorder:
    """A pytest plugin that adds up each file's measured time (setup, call and teardown of its
    tests) over a run, and writes them into the record at the end: files that ran are updated, the
    others kept."""

    def __init__(self, path: Path = DURATIONS) -> None:
        self.path = path
        self.seconds: Counter[str] = Counter()
        self.tests: Counter[str] = Counter()

    def pytest_runtest_logreport(self, report) -> None:
        file = file_of(report.nodeid)
        self.seconds[file] += report.duration
        if report.when == "setup":  # every test has one, a skipped test too
            self.tests[file] += 1

    def pytest_sessionfinish(self) -> None:
        self.write()

    def write(self) -> None:
        record = load(self.path)
        for file, seconds in self.seconds.items():
            record[file] = {"seconds": round(seconds, 1), "tests": self.tests[file]}
        self.path.write_text(dumps(record), encoding="utf-8")


def dumps(record: dict[str, dict[str, float]]) -> str:
    """The record as JSON, one file a line (reviewable diffs)."""
    lines = [f"  {json.dumps(file)}: {json.dumps(entry)}" for file, entry in sorted(record.items())]
    return "{\n" + ",\n".join(lines) + "\n}\n"
