"""Live edits of the ontology and the SWRL rules over REST (Table 2's "Onto" and "SWRL" kinds):
checked by Pellet, versioned in the Information State, live at once, readers see inferred values."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from gateway.config import Settings

from gw_testing import built_gateway


@pytest.fixture()
def gateway(tmp_path, mongo):
    settings = Settings(data_dir=str(tmp_path / "data"), engine={"rules_dir": str(tmp_path / "no-rules")},
                        streams={"queries_dir": None})
    with built_gateway(settings, mongo, tmp_path) as gw:
        yield gw


@pytest.fixture()
def client(gateway):
    with TestClient(gateway.app) as c:
        yield c


def _child_seat(client: TestClient, age: int) -> bool:
    body = {"individuals": [{"id": "kid", "types": ["Customer"], "properties": {"age": age}}]}
    answer = client.post("/api/reason", json=body)
    assert answer.status_code == 200, answer.text
    return any(f["subject"].endswith("kid") and f["predicate"].endswith("needsChildSeat") for f in answer.json()["inferred"])


def test_swrl_edit_is_live_versioned_and_rolled_back(client):
    current = client.get("/api/knowledge/swrl").json()
    assert "needsChildSeat" in current["text"] and current["version"] == 1 and current["author"] == "seed"
    assert _child_seat(client, 6) is True
    new_text = current["text"].replace("lessThan(?a, 7) -> needsChildSeat", "lessThan(?a, 5) -> needsChildSeat")
    put = client.put("/api/knowledge/swrl", json={"text": new_text, "comment": "#15", "base_hash": current["hash"]})
    assert put.status_code == 200, put.text
    assert put.json()["version"] == 2
    assert _child_seat(client, 6) is False  # live, no restart
    assert _child_seat(client, 4) is True
    history = client.get("/api/knowledge/swrl/history").json()
    assert [(h["event"], h["version"], h["comment"]) for h in history][:1] == [("deploy", 2, "#15")]
    stale = client.put("/api/knowledge/swrl", json={"text": new_text, "base_hash": current["hash"]})
    assert stale.status_code == 409 and stale.json()["version"] == 2
    assert [v["version"] for v in client.get("/api/knowledge/swrl/versions").json()] == [1, 2]
    assert client.post("/api/knowledge/swrl/rollback", json={"version": 1}).json()["version"] == 1
    assert _child_seat(client, 6) is True


def test_bad_swrl_is_refused_with_its_line_and_nothing_changes(client):
    before = client.get("/api/knowledge/swrl").json()["text"]
    broken = before + "\nCustomer(?c), age(?c, ?a -> Broken(?c)\n"
    check = client.post("/api/knowledge/swrl/check", json={"text": broken}).json()
    assert check["ok"] is False and check["errors"][0]["line"] == len(broken.splitlines())
    answer = client.put("/api/knowledge/swrl", json={"text": broken})
    assert answer.status_code == 422
    error = answer.json()["errors"][0]
    assert error["file"] == "teahouse.swrl" and error["line"] == len(broken.splitlines())
    assert client.get("/api/knowledge/swrl").json()["text"] == before


def test_bad_turtle_is_refused_and_nothing_changes(client):
    before = client.get("/api/knowledge/ontology").json()["text"]
    answer = client.put("/api/knowledge/ontology", json={"text": before + "\nthis is not turtle .\n"})
    assert answer.status_code == 422
    assert answer.json()["errors"][0]["file"] == "teahouse.ttl"
    assert client.get("/api/knowledge/ontology").json()["text"] == before


def test_ontology_value_edit_reaches_every_reader(client, gateway):
    current = client.get("/api/knowledge/ontology").json()
    assert "3.3" in current["text"]
    assert client.get("/api/knowledge/values").json()["values"]["kinect1.distanceToEntrance"] == 3.3
    new_text = current["text"].replace("\"3.3\"^^xsd:decimal", "\"2.5\"^^xsd:decimal")
    assert client.put("/api/knowledge/ontology", json={"text": new_text}).status_code == 200
    assert "2.5" in client.get("/api/knowledge/ontology").json()["text"]
    assert gateway.knowledge.value("kinect1.distanceToEntrance") == 2.5  # what workflows read
    assert client.get("/api/knowledge/values").json()["values"]["kinect1.distanceToEntrance"] == 2.5


def test_values_inferred_by_swrl_reach_workflows(client, gateway):
    """An SWRL rule's inferred value is a value like any other for the ontology's readers (workflow
    steps, query parameters), not only for /api/reason: the pour rule gives cup1.pourQuantity."""
    assert gateway.knowledge.value("cup1.pourQuantity") == 140.0  # 0.8 x 175, inferred by Pellet
    swrl = client.get("/api/knowledge/swrl").json()["text"]
    edited = swrl.replace("multiply(?quantity, ?capacity, 0.8)", "multiply(?quantity, ?capacity, 0.6)")
    assert client.put("/api/knowledge/swrl", json={"text": edited, "comment": "#16"}).status_code == 200
    assert gateway.knowledge.value("cup1.pourQuantity") == 105.0
    assert client.get("/api/knowledge/values").json()["values"]["cup1.pourQuantity"] == 105.0
