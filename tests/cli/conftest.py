"""Fixtures of the CLI tests: a config file in a temp folder, rule folders, a live gateway."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "api"))

from api_helpers import BROKEN, ServerThread, files, make_settings  # noqa: E402
from gw_testing import built_gateway  # noqa: E402

TOKENS = "cli-author:author:carol,cli-caller:caller:dave"


@pytest.fixture(scope="session")
def cli_home(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder with printeps.yaml, rules/greet (good) and broken/bad (does not compile)."""
    home = tmp_path_factory.mktemp("cli")
    settings = make_settings(home)
    greet = Path(settings.engine.rules_dir) / "greet"
    greet.mkdir(parents=True)
    for name, text in files("cli").items():
        (greet / name).write_text(text)
    bad = home / "broken" / "bad"
    bad.mkdir(parents=True)
    for name, text in BROKEN.items():
        (bad / name).write_text(text)
    config = {"data_dir": settings.data_dir, "engine": {"rules_dir": settings.engine.rules_dir}}
    (home / "printeps.yaml").write_text(yaml.safe_dump(config))
    return home


@pytest.fixture(scope="session")
def server(cli_home: Path, mongo) -> Iterator[ServerThread]:
    """A gateway with auth on (its own database), serving over real HTTP."""
    settings = make_settings(cli_home / "server", tokens=TOKENS)
    with built_gateway(settings, mongo, cli_home / "server") as gateway:
        srv = ServerThread(gateway.app).start()
        yield srv
        srv.stop()
