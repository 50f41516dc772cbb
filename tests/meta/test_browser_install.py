"""`make browser` installs the browser the tests drive first: the headless shell (tests/conftest.py
prefers it; the full chromium costs ~22% more CPU a page, docs/operations.md)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_make_browser_installs_the_browser_the_tests_prefer():
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    recipe = re.search(r"^browser:\n((?:\t.*\n)+)", makefile, re.M)
    assert recipe, "the Makefile has no browser target"
    preferred = Path("/usr/bin/chromium-headless-shell")
    assert f"command -v {preferred.name} " in recipe.group(1)
    assert re.search(rf"apt-get install -y -q {preferred.name}\b", recipe.group(1))
    conftest = (ROOT / "tests" / "conftest.py").read_text(encoding="utf-8")
    candidates = re.search(r"^CHROMIUM = next\(\(path for path in \(([^)]*)\)", conftest, re.M)
    assert candidates, "tests/conftest.py no longer chooses CHROMIUM from a list of paths"
    assert candidates.group(1).split(",")[0].strip().strip('"') == str(preferred)
