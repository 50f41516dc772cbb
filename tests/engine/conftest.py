from __future__ import annotations

import pytest

from gateway.config import Settings
from gateway.engine import Engine

from engine_samples import RULES, TYPES


@pytest.fixture()
def engine(tmp_path) -> Engine:
    return Engine(Settings(data_dir=str(tmp_path / "data"), engine={"rules_dir": str(tmp_path / "rules")}))


@pytest.fixture()
def simple_files() -> dict[str, str]:
    return {"types.drl": TYPES, "rules.drl": RULES}
