"""REST for editing queries and mappings (the workbench's Streams section): dry validation with
line and column, saves with a comment and the base version, one version's definition, mapping
YAML with the line of the bad key, previews of a draft, rollback."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from gateway.config import Settings

from csparql_scenarios import CUSTOMER_QUERY
from gw_testing import built_gateway

COUNT_QUERY = """REGISTER QUERY EditCount AS
PREFIX printeps: <http://printeps.org/cafe/entrance/>
SELECT (COUNT(?s) AS ?n)
FROM STREAM <http://printeps.org/cafe/entrance> [RANGE 2s STEP 1s]
WHERE { ?s a printeps:Customer . }
"""


@pytest.fixture()
def client(settings, mongo, tmp_path):
    full = Settings.model_validate({"data_dir": str(tmp_path / "var"), "engine": {"rules_dir": str(tmp_path / "rules")},
                                    "streams": settings.model_dump()})
    with built_gateway(full, mongo, tmp_path) as gw:
        yield TestClient(gw.app)


def test_validate_checks_like_a_registration_and_changes_nothing(client):
    r = client.post("/api/queries/validate", json={"query": COUNT_QUERY})
    assert r.status_code == 200 and r.json()["ok"] is True, r.text
    body = r.json()
    assert body["name"] == "EditCount" and body["exists"] is False and body["version"] is None
    assert body["query"]["windows"][0]["range_ms"] == 2000
    assert client.get("/api/queries/EditCount").status_code == 404  # nothing registered
    bad = COUNT_QUERY.replace("WHERE {", "WHERE {\n  ?s printeps:age ?a ; .\n  FILTER(?a >>> 3)")
    errors = client.post("/api/queries/validate", json={"query": bad}).json()
    assert errors["ok"] is False
    assert errors["errors"][0]["field"] == "query" and errors["errors"][0]["line"] >= 6, errors
    report = client.post("/api/queries/validate", json={"query": COUNT_QUERY, "report": "sometimes"}).json()
    assert report["ok"] is False and report["errors"][0]["field"] == "report"
    rules = client.post("/api/queries/validate", json={"query": COUNT_QUERY, "rules": {"ruleset": 3}}).json()
    assert rules["ok"] is False and rules["errors"][0]["field"] == "rules"


def test_saves_carry_a_comment_and_refuse_a_stale_base_version(client):
    r = client.post("/api/queries", json={"query": COUNT_QUERY, "comment": "first", "base_version": 0})
    assert r.status_code == 201, r.text
    assert client.get("/api/queries/EditCount").json()["version"] == 1
    assert client.post("/api/queries/validate", json={"query": COUNT_QUERY}).json()["exists"] is True
    wider = COUNT_QUERY.replace("RANGE 2s", "RANGE 4s")
    r = client.post("/api/queries", json={"query": wider, "replace": True, "comment": "wider", "base_version": 1})
    assert r.status_code == 201 and r.json()["version"] == 2
    stale = client.post("/api/queries", json={"query": COUNT_QUERY, "replace": True, "base_version": 1})
    assert stale.status_code == 409 and stale.json()["current"] == 2
    assert client.get("/api/queries/EditCount").json()["windows"][0]["range_ms"] == 4000  # unchanged
    versions = client.get("/api/queries/EditCount/versions").json()
    assert [(v["version"], v["comment"]) for v in versions] == [(1, "first"), (2, "wider")]
    one = client.get("/api/queries/EditCount/versions/1").json()
    assert one["text"] == COUNT_QUERY and one["current"] is False and one["report"] is None
    assert client.get("/api/queries/EditCount/versions/9").status_code == 404
    missing = client.post("/api/queries/EditCount/rollback", json={"version": 9})  # as for mappings: 404, named
    assert missing.status_code == 404 and "has no version 9" in missing.text
    assert client.post("/api/queries/EditCount/rollback", json={"version": 1}).status_code == 200
    assert client.get("/api/queries/EditCount/versions/1").json()["current"] is True
    assert [q["version"] for q in client.get("/api/queries").json()["queries"] if q["name"] == "EditCount"] == [1]


def test_a_bad_report_policy_is_named_on_save(client):
    r = client.post("/api/queries", json={"query": CUSTOMER_QUERY, "report": "whenever"})
    assert r.status_code == 422 and r.json()["field"] == "report"


MAPPING_YAML = """subject: "printeps:table_{id}"
type: printeps:Table
fields:
  seats: printeps:seats
children:
  people:
    link: printeps:hasPerson
    subject: "printeps:{id}"
    fields:
      name: printeps:name
"""


def test_mapping_yaml_errors_point_at_their_line(client):
    bad = MAPPING_YAML.replace("link: printeps:hasPerson", "lnk: printeps:hasPerson")
    r = client.post("/api/mappings/validate", json={"text": bad})
    error = r.json()["errors"][0]
    assert r.json()["ok"] is False and error["where"] == "mapping.children.people" and error["line"] == 6, error
    r = client.post("/api/mappings/validate", json={"text": "subject: [unclosed\n"})
    assert r.json()["ok"] is False and r.json()["errors"][0]["line"] >= 1
    r = client.put("/api/mappings/edit_table", json={"text": MAPPING_YAML.replace("printeps:seats", "no such:prefix x")})
    assert r.status_code == 422 and r.json()["line"] == 4 and r.json()["where"] == "mapping.fields.seats", r.text
    assert client.get("/api/mappings/edit_table").status_code == 404  # nothing saved


def test_mapping_text_saves_previews_and_rolls_back(client):
    r = client.put("/api/mappings/edit_table", json={"text": MAPPING_YAML, "comment": "new", "base_version": 0})
    assert r.status_code == 201 and r.json()["version"] == 1, r.text
    got = client.get("/api/mappings/edit_table").json()
    assert "printeps:hasPerson" in got["text"] and got["version"] == 1
    message = {"id": "t2", "seats": 4, "people": [{"id": "p1", "name": "Ann"}]}
    live = client.post("/api/mappings/edit_table/preview", json={"message": message}).json()["triples"]
    assert any("hasPerson" in t[1] for t in live)
    draft = MAPPING_YAML.replace("printeps:hasPerson", "printeps:seatedPerson")
    drafted = client.post("/api/mappings/edit_table/preview", json={"message": message, "text": draft}).json()["triples"]
    assert any("seatedPerson" in t[1] for t in drafted) and not any("hasPerson" in t[1] for t in drafted)
    assert client.get("/api/mappings/edit_table").json()["version"] == 1  # a draft preview saves nothing
    r = client.put("/api/mappings/edit_table", json={"text": draft, "comment": "renamed", "base_version": 1})
    assert r.status_code == 201 and r.json()["version"] == 2
    stale = client.put("/api/mappings/edit_table", json={"text": MAPPING_YAML, "base_version": 1})
    assert stale.status_code == 409 and stale.json()["current"] == 2
    assert client.get("/api/mappings/edit_table/versions/1").json()["current"] is False
    assert client.post("/api/mappings/edit_table/rollback", json={"version": 1}).json()["version"] == 1
    assert client.get("/api/mappings/edit_table/versions/1").json()["current"] is True
    live = client.post("/api/mappings/edit_table/preview", json={"message": message}).json()["triples"]
    assert any("hasPerson" in t[1] for t in live)
    assert client.post("/api/mappings/edit_table/rollback", json={"version": 7}).status_code == 404


def test_a_deleted_mapping_stays_deleted(client):
    """The entrance mapping is data (seeded from ontology/mappings): deleting it stops serving it;
    no copy in code comes back in its place."""
    message = {"id": "e1", "number_of_customers": 1, "customers": [{"id": "c1", "distance": 2.0}]}
    preview = client.post("/api/mappings/entrance/preview", json={"message": message, "timestamp": 1000})
    assert preview.status_code == 200, preview.text
    assert client.delete("/api/mappings/entrance").status_code == 200
    assert client.get("/api/mappings/entrance").status_code == 404
    assert "entrance" not in [m["name"] for m in client.get("/api/mappings").json()]
