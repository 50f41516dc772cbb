"""The workers get the longest test files first, by measured time (tests/scheduling.py)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path
from types import SimpleNamespace

import scheduling

ROOT = Path(__file__).resolve().parents[2]


def test_the_longest_files_go_first_and_a_unit_stays_together():
    seconds = {"a.py": 5.0, "b.py": 40.0, "ros/x.py": 10.0, "ros/y.py": 20.0, "c.py": 1.0}
    unit = lambda file: "ROS" if file.startswith("ros/") else file  # noqa: E731
    order = scheduling.longest_first(["a.py", "ros/x.py", "b.py", "c.py", "ros/y.py"], seconds, unit)
    assert order == ["b.py", "ros/x.py", "ros/y.py", "a.py", "c.py"]  # the unit counts 30 s, its order kept


def test_a_new_file_is_estimated_from_its_tests_and_a_subset_in_proportion():
    record = {"long.py": {"seconds": 90.0, "tests": 3}, "short.py": {"seconds": 10.0, "tests": 7}}
    expected = scheduling.estimated_seconds(record, Counter({"long.py": 1, "short.py": 7, "new.py": 4}))
    assert expected == {"long.py": 30.0, "short.py": 10.0, "new.py": 40.0}  # 100 s / 10 tests a test


def test_a_run_records_each_files_time_and_keeps_the_others(tmp_path: Path):
    path = tmp_path / "durations.json"
    path.write_text(scheduling.dumps({"tests/old.py": {"seconds": 3.0, "tests": 1},
                                      "tests/a.py": {"seconds": 99.0, "tests": 9}}))
    recorder = scheduling.Recorder(path)
    for nodeid, when, duration in [("tests/a.py::t1", "setup", 0.5), ("tests/a.py::t1", "call", 2.0),
                                   ("tests/a.py::t1", "teardown", 0.25), ("tests/a.py::t2", "setup", 0.05),
                                   ("tests/b.py::t", "setup", 1.0)]:
        recorder.pytest_runtest_logreport(SimpleNamespace(nodeid=nodeid, when=when, duration=duration))
    recorder.pytest_sessionfinish()
    assert json.loads(path.read_text()) == {"tests/a.py": {"seconds": 2.8, "tests": 2},
                                            "tests/b.py": {"seconds": 1.0, "tests": 1},
                                            "tests/old.py": {"seconds": 3.0, "tests": 1}}


def test_the_record_names_only_test_files_that_exist():
    record = scheduling.load()
    assert len(record) > 100, "tests/durations.json is missing or nearly empty: make durations"
    gone = [file for file in record if not (ROOT / file).is_file()]
    assert not gone, f"tests/durations.json names files that are gone (make durations, or delete them): {gone}"


def _xdist_run(root: Path, files: dict[str, str]) -> subprocess.CompletedProcess:
    """pytest on one xdist worker over ``files`` (under ``root/tests``) with the suite's own conftest."""
    tests = root / "tests"
    tests.mkdir()
    for helper in ("conftest.py", "scheduling.py", "gw_testing.py", "ci_skips.py", "skip_allowlist.txt"):
        (tests / helper).write_text((ROOT / "tests" / helper).read_text())
    for name, text in files.items():
        (tests / name).write_text(text)
    return subprocess.run([sys.executable, "-m", "pytest", "-n", "1", "--dist", "loadfile", "-v", "-p", "no:cacheprovider",
                           "-p", "no:randomly", "tests"], cwd=root, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(ROOT), "CI": ""})


def test_xdist_workers_collect_the_files_longest_first(tmp_path: Path):
    """A worker of a real xdist run gets the recorded longest file first, against xdist's
    own order (most tests first)."""
    run = _xdist_run(tmp_path, {
        "test_many.py": "".join(f"def test_{i}():\n    pass\n" for i in range(5)),
        "test_one.py": "def test_long():\n    pass\n",
        "durations.json": scheduling.dumps({"tests/test_many.py": {"seconds": 1.0, "tests": 5},
                                            "tests/test_one.py": {"seconds": 60.0, "tests": 1}})})
    passed = [line for line in run.stdout.splitlines() if "PASSED" in line]
    assert run.returncode == 0, run.stdout + run.stderr
    assert "test_one.py::test_long" in passed[0], passed


def test_a_ros_test_outside_the_ros_unit_fails_under_xdist(tmp_path: Path):
    """The ROS tests run as one unit on one worker (tests/conftest.py, ROS_UNIT); one marked `ros`
    elsewhere fails, naming the list to add its file to."""
    run = _xdist_run(tmp_path, {"test_elsewhere.py": "import pytest\n\n@pytest.mark.ros\ndef test_topic():\n    pass\n"})
    assert run.returncode == 1, run.stdout + run.stderr
    assert "is marked `ros` but its file is not in ROS_UNIT" in run.stdout
