"""The CI rule of tests/ci_skips.py, run on a small suite of its own: with CI=true a skip fails the
run unless the allow-list names it; without CI a skip stays a skip."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parents[1]
SUITE = '''
import pytest

def test_passes():
    pass

def test_skips_without_reason_to():
    pytest.skip("no widget installed")

@pytest.mark.parametrize("n", [1, 2])
def test_allowed(n):
    pytest.skip("an optional alternative")
'''


@pytest.fixture
def small_suite(tmp_path: Path) -> Path:
    (tmp_path / "conftest.py").write_text("from ci_skips import *  # noqa: F401,F403\n")
    (tmp_path / "test_small.py").write_text(SUITE)
    (tmp_path / "test_whole_module.py").write_text('import pytest\npytest.importorskip("no_such_module_here")\n'
                                                  "def test_never():\n    pass\n")
    (tmp_path / "allow.txt").write_text("# comment\ntest_small.py::test_allowed  # optional on purpose\n")
    return tmp_path


def run(folder: Path, ci: str | None, allowlist: str = "allow.txt", *options: str) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    env.update(PYTHONPATH=os.pathsep.join([str(TESTS), env.get("PYTHONPATH", "")]),
               PRINTEPS_SKIP_ALLOWLIST=str(folder / allowlist))
    if ci is not None:
        env["CI"] = ci
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider", *options,
                           "--rootdir", str(folder), str(folder)], cwd=folder, env=env, capture_output=True, text=True,
                          timeout=300)  # a loaded 2-core machine: an xdist run took 3 min


def test_in_ci_an_unlisted_skip_fails_and_names_the_allowlist(small_suite):
    out = run(small_suite, "true")
    assert out.returncode == 1, out.stdout
    assert "test_skips_without_reason_to was skipped under CI=true" in out.stdout
    assert "no widget installed" in out.stdout and "allow.txt" in out.stdout
    # a module skipped as a whole fails the run too, named at its end
    assert "FAILED (skipped module) test_whole_module.py was skipped under CI=true" in out.stdout
    # the listed test (every parameter) is still a skip, the passing one passes
    assert "1 failed, 1 passed, 3 skipped" in out.stdout, out.stdout


def test_in_ci_on_xdist_workers_an_unlisted_skip_still_fails(small_suite):
    """`make test` runs the suite on pytest-xdist workers: the skips found there (in a test, or of
    a whole module at collection) reach the controller and still fail the run."""
    out = run(small_suite, "true", "allow.txt", "-n", "1", "--dist", "loadfile")
    assert out.returncode == 1, out.stdout
    assert "test_skips_without_reason_to was skipped under CI=true" in out.stdout
    assert "FAILED (skipped module) test_whole_module.py was skipped under CI=true" in out.stdout
    assert "1 failed, 1 passed, 3 skipped" in out.stdout, out.stdout


def test_outside_ci_skips_stay_skips(small_suite):
    for ci in (None, "0"):
        out = run(small_suite, ci)
        assert out.returncode == 0, out.stdout
        assert "1 passed, 4 skipped" in out.stdout, out.stdout


def test_an_allowlist_entry_without_a_reason_is_refused(small_suite):
    (small_suite / "bad.txt").write_text("test_small.py::test_allowed\n")
    out = run(small_suite, "true", "bad.txt")
    assert out.returncode != 0
    assert "bad.txt:1" in out.stdout + out.stderr and "has no reason" in out.stdout + out.stderr


def test_the_repository_allowlist_is_short_and_every_entry_names_a_test():
    from ci_skips import DEFAULT_ALLOWLIST, allowed_skips

    entries = allowed_skips(DEFAULT_ALLOWLIST)
    assert len(entries) <= 5, entries
    root = TESTS.parent
    for test_id in entries:
        path, _, name = test_id.partition("::")
        assert (root / path).exists(), test_id
        assert f"def {name.split('::')[-1]}(" in (root / path).read_text(), test_id
