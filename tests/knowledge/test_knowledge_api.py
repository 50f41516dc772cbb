"""Live edits of the ontology and the SWRL rules over REST (Table 2's "Onto" and "SWRL" kinds)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from gateway import jvm
from gateway.config import PROJECT_ROOT, Settings
from gateway.engine import Engine
from gateway.server import build_app

ONTOLOGY = PROJECT_ROOT / "ontology"


@pytest.fixture()
def client(tmp_path):
    onto_dir = tmp_path / "ontology"
    shutil.copytree(ONTOLOGY, onto_dir)
    settings = Settings(
        data_dir=str(tmp_path / "data"),
        engine={"rules_dir": str(tmp_path / "no-rules")},
        streams={"ontology_file": str(onto_dir / "teahouse.ttl"), "swrl_file": str(onto_dir / "teahouse.swrl"),
                 "queries_dir": str(onto_dir / "queries")},
    )
    jvm.start(settings.jvm)  # main thread, before any worker thread touches Java
    app, _ = build_app(settings, Engine(settings), None)
    with TestClient(app) as c:
        c.paths = {"ontology": onto_dir / "teahouse.ttl", "swrl": onto_dir / "teahouse.swrl"}  # type: ignore[attr-defined]
        yield c


def _child_seat(client: TestClient, age: int) -> bool:
    body = {"individuals": [{"id": "kid", "types": ["Customer"], "properties": {"age": age}}]}
    answer = client.post("/api/reason", json=body)
    assert answer.status_code == 200, answer.text
    return any(f["subject"].endswith("kid") and f["predicate"].endswith("needsChildSeat") for f in answer.json()["inferred"])


def test_swrl_edit_is_live_and_kept(client):
    current = client.get("/api/knowledge/swrl").json()
    assert "needsChildSeat" in current["text"]
    assert _child_seat(client, 6) is True
    new_text = current["text"].replace("lessThan(?a, 7) -> needsChildSeat", "lessThan(?a, 5) -> needsChildSeat")
    put = client.put("/api/knowledge/swrl", json={"text": new_text, "comment": "#15", "base_hash": current["hash"]})
    assert put.status_code == 200, put.text
    assert _child_seat(client, 6) is False  # live, no restart
    assert _child_seat(client, 4) is True
    assert len(client.get("/api/knowledge/swrl/history").json()) == 1
    stale = client.put("/api/knowledge/swrl", json={"text": new_text, "base_hash": current["hash"]})
    assert stale.status_code == 409


def test_bad_swrl_is_refused_with_its_line_and_nothing_changes(client):
    before = client.paths["swrl"].read_text()
    broken = before + "\nCustomer(?c), age(?c, ?a -> Broken(?c)\n"
    answer = client.put("/api/knowledge/swrl", json={"text": broken})
    assert answer.status_code == 422
    error = answer.json()["errors"][0]
    assert error["file"] == "teahouse.swrl" and error["line"] == len(broken.splitlines())
    assert client.paths["swrl"].read_text() == before


def test_bad_turtle_is_refused_and_nothing_changes(client):
    before = client.paths["ontology"].read_text()
    answer = client.put("/api/knowledge/ontology", json={"text": before + "\nthis is not turtle .\n"})
    assert answer.status_code == 422
    assert answer.json()["errors"][0]["file"] == "teahouse.ttl"
    assert client.paths["ontology"].read_text() == before


def test_ontology_value_edit(client):
    current = client.get("/api/knowledge/ontology").json()
    assert "3.3" in current["text"]
    new_text = current["text"].replace("\"3.3\"^^xsd:decimal", "\"2.5\"^^xsd:decimal")
    assert client.put("/api/knowledge/ontology", json={"text": new_text}).status_code == 200
    assert "2.5" in client.paths["ontology"].read_text()
