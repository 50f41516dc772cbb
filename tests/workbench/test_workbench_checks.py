"""The browser-side checks (web/src/checks.js) under node's own test runner."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from gateway.config import PROJECT_ROOT


def test_browser_side_checks():
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed (only needed to test web/src/checks.js)")
    result = subprocess.run([node, "--test", "test/"], cwd=PROJECT_ROOT / "web", capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stdout + result.stderr
