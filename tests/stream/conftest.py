from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from gateway.config import StreamSettings
from gateway.stream import StreamEngine

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture()
def ontology_copy(tmp_path) -> Path:
    """A private copy of the teahouse ontology the test may edit."""
    path = tmp_path / "knowledge" / "teahouse.ttl"  # the one ontology file of streams.knowledge_dir
    path.parent.mkdir()
    shutil.copy(ROOT / "ontology" / "teahouse.ttl", path)
    return path


@pytest.fixture()
def settings(ontology_copy) -> StreamSettings:
    return StreamSettings(knowledge_dir=str(ontology_copy.parent), queries_dir=None)


@pytest.fixture()
def engine(settings) -> StreamEngine:
    return StreamEngine(settings)
