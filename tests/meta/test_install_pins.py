"""`make install` installs nothing that floats (issue 25: reproducible installs).

The lock files pin every dependency with its hash; what is left are the installs around them:
pip itself, and the gateway's own editable install, whose build backend an isolated build would
fetch at its newest. Both are read from the Makefile's install recipe as it is written.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[2]


def install_recipe(makefile: str) -> list[str]:
    """The `pip install` commands of the recipe that builds the install stamp (``$(STAMP):``)."""
    lines = makefile.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("$(STAMP):"))
    recipe = []
    for line in lines[start + 1:]:
        if not line.startswith("\t"):
            break
        recipe.append(line.strip())
    return [line for line in recipe if re.search(r"\bpip install\b", line)]


def floating(command: str, variables: dict[str, str]) -> str | None:
    """Why ``command`` may install something unpinned, or None."""
    if "--upgrade" in command or re.search(r"(^|\s)-U(\s|$)", command):
        return "upgrades to whatever is newest"
    if "--require-hashes" in command and " -r " in command:
        return None  # a lock file
    if " -e " in command:
        return None if "--no-build-isolation" in command else "an isolated build fetches the newest build backend"
    pinned = re.search(r"install -q (\S+)==(\S+)$", command)
    if pinned:
        version = re.sub(r"\$\((\w+)\)", lambda m: variables.get(m.group(1), m.group(0)), pinned.group(2))
        return None if re.fullmatch(r"\d+(\.\d+)*", version) else f"pin {version!r} is not an exact version"
    return "installs without a lock, a hash or an exact pin"


def makefile_variables(makefile: str) -> dict[str, str]:
    return dict(re.findall(r"^(\w+)\s*:=\s*(\S+)", makefile, re.MULTILINE))


def test_every_install_of_make_install_is_pinned():
    makefile = (ROOT / "Makefile").read_text(encoding="utf-8")
    commands = install_recipe(makefile)
    assert len(commands) >= 4, commands  # pip, the two lock files, the gateway itself
    variables = makefile_variables(makefile)
    problems = {command: why for command in commands if (why := floating(command, variables))}
    assert problems == {}


def test_the_check_finds_what_floats():
    variables = {"PIP_VERSION": "26.3"}
    assert floating("$(BIN)/pip install -q --upgrade pip", variables)
    assert floating("$(BIN)/pip install -q --no-deps -e .", variables)
    assert floating("$(BIN)/pip install -q requests", variables)
    assert floating("$(BIN)/pip install -q pip==$(NOT_SET)", variables)
    assert floating("$(BIN)/pip install -q pip==$(PIP_VERSION)", variables) is None
    assert floating("$(BIN)/pip install -q --no-deps --no-build-isolation -e .", variables) is None
    assert floating("$(BIN)/pip install -q --require-hashes -r $(LOCK)", variables) is None


def test_the_locked_setuptools_can_build_the_package():
    """The editable install uses the lock's setuptools: it must meet the build requirement, and the
    metadata must use no form that setuptools has announced it will stop reading (a license table)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    assert isinstance(project["project"]["license"], str)  # an SPDX expression (PEP 639)
    required = next(Requirement(r) for r in project["build-system"]["requires"] if r.startswith("setuptools"))
    lock = (ROOT / "requirements.lock").read_text(encoding="utf-8")
    locked = re.search(r"^setuptools==(\S+)", lock, re.MULTILINE).group(1)
    assert required.specifier.contains(locked), (str(required), locked)
