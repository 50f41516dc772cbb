"""The knowledge editor's REST API: class tree, typed individuals, one value or one SWRL rule changed
(checked, versioned, live; bad input names the field and changes nothing), and what Pellet infers."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from gateway.config import Settings

from gw_testing import built_gateway


@pytest.fixture(scope="module")
def gateway(tmp_path_factory, mongo):
    tmp_path = tmp_path_factory.mktemp("knowledge-editor")
    settings = Settings(data_dir=str(tmp_path / "data"), engine={"rules_dir": str(tmp_path / "no-rules")},
                        streams={"queries_dir": None})
    with built_gateway(settings, mongo, tmp_path) as gw:
        yield gw


@pytest.fixture()
def client(gateway):
    with TestClient(gateway.app) as c:
        yield c
        # every test starts from the seeded texts
        for kind in ("ontology", "swrl"):
            if c.get(f"/api/knowledge/{kind}").json()["version"] != 1:
                assert c.post(f"/api/knowledge/{kind}/rollback", json={"version": 1}).status_code == 200


def _value(individuals: dict, name: str, prop: str) -> dict:
    ind = next(i for i in individuals["individuals"] if i["name"] == name)
    return next(v for v in ind["values"] if v["property"] == prop)


def _move_to(client: TestClient) -> list[tuple[float, float]]:
    run = client.post("/api/workflows/show_to_seat/run", json={"inputs": {}}).json()
    assert run["status"] == "succeeded", run
    return [(round(float(s["params"]["x"]), 2), round(float(s["params"]["y"]), 2)) for s in run["steps"]
            if s["type"] == "module" and s["module"] == "move_to"]


def test_class_tree_nests_subclasses_with_their_individuals(client):
    tree = client.get("/api/knowledge/classes").json()["classes"]
    machine = next(c for c in tree if c["name"] == "Machine")
    robot = next(c for c in machine["children"] if c["name"] == "Robot")
    pepper = next(c for c in robot["children"] if c["name"] == "Pepper")
    assert pepper["individuals"] == ["pepper1"]
    assert "Robot" not in [c["name"] for c in tree]


def test_individuals_have_typed_values_asserted_and_inferred(client):
    body = client.get("/api/knowledge/individuals").json()
    distance = _value(body, "pepper1", "robotToHumanDistance")
    assert distance == {"property": "robotToHumanDistance", "lexical": "1.0", "value": 1.0, "datatype": "decimal",
                        "inferred": False, "unit": "metres", "limits": {"minInclusive": "0", "maxInclusive": "5"},
                        "expects": "a number in metres from 0 to 5, e.g. 1.0"}
    poured = _value(body, "cup1", "pourQuantity")
    assert poured["inferred"] is True and poured["value"] == 140.0 and poured["rules"] == [7]
    ranges = {p["name"]: p["range"] for p in body["properties"]}
    table_time = next(p for p in body["properties"] if p["name"] == "tableEmptyTime")
    assert (table_time["unit"], table_time["limits"]) == ("seconds", {"minInclusive": "0", "maxInclusive": "110"})
    assert ranges["emptyCupReactionTime"] == "decimal" and ranges["needsChildSeat"] == "boolean"
    assert client.get("/api/knowledge/individuals/nobody").status_code == 404


def test_one_value_is_saved_as_a_version_and_is_live_for_workflows(client, gateway):
    before = client.get("/api/knowledge/ontology").json()
    assert _move_to(client)[0] == (2.0, 0.0)
    answer = client.put("/api/knowledge/individuals/pepper1/values/robotToHumanDistance",
                        json={"value": "1.5", "comment": "#12", "base_hash": before["hash"]})
    assert answer.status_code == 200, answer.text
    assert answer.json()["version"] == 2 and answer.json()["value"] == 1.5
    assert gateway.knowledge.value("pepper1.robotToHumanDistance") == 1.5
    assert _move_to(client)[0] == (2.5, 0.0)  # the workflow sees it at once
    after = client.get("/api/knowledge/ontology").json()["text"]
    changed = [(a, b) for a, b in zip(before["text"].splitlines(), after.splitlines()) if a != b]
    assert changed == [('    printeps:robotToHumanDistance "1.0"^^xsd:decimal ;',
                        '    printeps:robotToHumanDistance "1.5"^^xsd:decimal ;')]
    history = client.get("/api/knowledge/ontology/history").json()
    assert (history[0]["version"], history[0]["comment"]) == (2, "#12")
    stale = client.put("/api/knowledge/individuals/pepper1/values/robotToHumanDistance",
                       json={"value": "1.2", "base_hash": before["hash"]})
    assert stale.status_code == 409
    assert client.post("/api/knowledge/ontology/rollback", json={"version": 1}).status_code == 200
    assert _move_to(client)[0] == (2.0, 0.0)


@pytest.mark.parametrize("prop, value, field, says", [
    ("robotToHumanDistance", "abc", "value", "robotToHumanDistance: 'abc' is not a number in metres from 0 to 5, e.g. 1.0"),
    ("robotToHumanDistance", "-0.5", "value", "robotToHumanDistance: -0.5 metres is below the least allowed, 0 metres; "
                                              "give a number in metres from 0 to 5, e.g. 1.0"),
    ("robotToHumanDistance", "7", "value", "7 metres is above the most allowed, 5 metres"),
    ("robotToHumanDistance", "", "value", "robotToHumanDistance: a value is needed"),
    ("robotPosition", "kitchen1", "property", "robotPosition is an object property"),
    ("noSuchThing", "1", "property", "'noSuchThing' is not a property of the ontology"),
])
def test_a_bad_value_names_the_field_and_changes_nothing(client, gateway, prop, value, field, says):
    before = client.get("/api/knowledge/ontology").json()
    answer = client.put(f"/api/knowledge/individuals/pepper1/values/{prop}", json={"value": value})
    assert answer.status_code == 422, answer.text
    assert answer.json()["errors"][0]["field"] == field and says in answer.json()["error"]
    assert client.get("/api/knowledge/ontology").json() == before
    assert gateway.knowledge.value("pepper1.robotToHumanDistance") == 1.0


def test_a_value_the_individual_lacks_is_added(client, gateway):
    answer = client.put("/api/knowledge/individuals/hsr1/values/robotToTableDistance", json={"value": 0.3})
    assert answer.status_code == 200, answer.text
    assert gateway.knowledge.value("hsr1.robotToTableDistance") == 0.3


def test_rules_are_listed_one_by_one_in_words(client):
    rules = client.get("/api/knowledge/swrl/rules").json()["rules"]
    child = rules[5]
    assert child["number"] == 6 and child["text"].startswith("Customer(?c), age(?c, ?a), lessThan(?a, 7)")
    assert child["readable"] == "If ?c is a Customer and ?c's age is ?a and ?a < 7, then ?c needs child seat."
    assert child["comment"].startswith("Child seats")
    assert [a["name"] for a in child["body"]] == ["Customer", "age", "lessThan"]
    assert client.get("/api/knowledge/swrl/rules/6").json()["text"] == child["text"]
    assert client.get("/api/knowledge/swrl/rules/99").status_code == 404


def _child_seat(client: TestClient, age: int) -> bool:
    tried = client.post("/api/knowledge/try", json={"individual": {"id": "kid", "types": ["Customer"],
                                                                   "properties": {"age": age}}}).json()
    return any(v["property"] == "needsChildSeat" for v in tried["values"])


def test_one_rule_is_checked_saved_and_live(client, gateway):
    rule = client.get("/api/knowledge/swrl/rules/6").json()
    new = rule["text"].replace("lessThan(?a, 7)", "lessThan(?a, 6)")
    assert client.post("/api/knowledge/swrl/rules/6/check", json={"text": new}).json() == {"ok": True, "errors": [],
                                                                                           "changes": []}
    assert _child_seat(client, 6) is True
    saved = client.put("/api/knowledge/swrl/rules/6", json={"text": new, "comment": "#15", "base_hash": rule["hash"]})
    assert saved.status_code == 200, saved.text
    assert saved.json()["version"] == 2 and "?a < 6" in saved.json()["readable"]
    assert _child_seat(client, 6) is False and _child_seat(client, 5) is True
    pour = client.get("/api/knowledge/swrl/rules/7").json()["text"]
    check = client.post("/api/knowledge/swrl/rules/7/check", json={"text": pour.replace("0.8", "0.7")}).json()
    assert check["changes"] == [{"value": "cup1.pourQuantity", "before": "140.0", "after": "122.5"}]
    assert client.put("/api/knowledge/swrl/rules/7", json={"text": pour.replace("0.8", "0.7")}).status_code == 200
    assert gateway.knowledge.value("cup1.pourQuantity") == pytest.approx(122.5)  # what workflows read


@pytest.mark.parametrize("text, column, atom, says", [
    ("Customer(?c), age(?c, ?a), lessThan(?a 7) -> needsChildSeat(?c, true)", 40, "lessThan(?a 7",
     "expected ',' or ')'"),
    ("Customer(?c), agee(?c, ?a), lessThan(?a, 7) -> needsChildSeat(?c, true)", 15, "agee(?c, ?a)",
     "'agee' is not a class, property or built-in"),
    ("Customer(?c), age(?c, ?a), lessThan(?a, 7) -> needsChildSeat(?d, true)", 47, "needsChildSeat(?d, true)",
     "?d in the conclusion"),
])
def test_a_bad_rule_says_where_and_changes_nothing(client, gateway, text, column, atom, says):
    before = client.get("/api/knowledge/swrl").json()
    check = client.post("/api/knowledge/swrl/rules/6/check", json={"text": text}).json()
    assert check["ok"] is False
    error = check["errors"][0]
    assert (error["rule"], error["line"], error["column"], error["atom"]) == (6, 17, column, atom)
    assert says in error["message"] and error["message"].startswith("rule 6: ")
    answer = client.put("/api/knowledge/swrl/rules/6", json={"text": text})
    assert answer.status_code == 422 and answer.json()["errors"][0]["column"] == column
    assert client.get("/api/knowledge/swrl").json() == before
    assert _child_seat(client, 6) is True


@pytest.mark.parametrize("text, says", [
    ('Cup(?c) -> hasCup(?c, "x")', 'hasCup: "x" is not a ?variable or an individual of the ontology'),
    ("Cup(?c) -> cupCapacity(?c, big)", "cupCapacity: big is not a ?variable or a value"),
    ("Cup(nobody) -> Child(nobody)", "Cup: nobody is not a ?variable or an individual"),
])
def test_arguments_of_the_wrong_kind_are_named(client, text, says):
    error = client.post("/api/knowledge/swrl/rules/7/check", json={"text": text}).json()["errors"][0]
    assert says in error["message"] and error["column"] > 0 and error["atom"]


def test_a_rule_pellet_finds_inconsistent_is_refused_with_its_rule(client, gateway):
    # cup1 is a Cup: giving every cup a text capacity contradicts cupCapacity's range (xsd:decimal)
    text = 'Cup(?c) -> cupCapacity(?c, "big")'
    check = client.post("/api/knowledge/swrl/rules/7/check", json={"text": text}).json()
    assert check["ok"] is False
    error = check["errors"][0]
    assert (error["rule"], error["line"]) == (7, 20)
    assert error["message"].startswith("rule 7: Pellet finds the ontology and the rules inconsistent")
    # Pellet gives no position: the error points at the rule's conclusion, all the rule adds
    assert (error["column"], error["atom"]) == (text.index("cupCapacity") + 1, 'cupCapacity(?c, "big")')
    assert client.put("/api/knowledge/swrl/rules/7", json={"text": text}).status_code == 422
    assert gateway.knowledge.value("cup1.pourQuantity") == 140.0


def test_what_pellet_infers_for_an_individual(client):
    pepper = client.get("/api/knowledge/individuals/pepper1/inferred").json()
    robot = next(t for t in pepper["types"] if t["class"] == "Robot")
    assert robot["because"] == "Pepper is a kind of Robot"
    cup = client.get("/api/knowledge/individuals/cup1/inferred").json()
    assert [(v["property"], v["value"], v["rules"]) for v in cup["values"]] == [("pourQuantity", 140.0, [7])]
    kid = client.post("/api/knowledge/try", json={"individual": {"id": "kid", "types": ["Customer"],
                                                                 "properties": {"age": 4}}}).json()
    assert next(t for t in kid["types"] if t["class"] == "Child")["rules"] == [5]
    assert [(v["property"], v["value"], v["rules"]) for v in kid["values"]] == [("needsChildSeat", True, [6])]
    bad = client.post("/api/knowledge/try", json={"individual": {"id": "kid", "types": ["Nope"]}})
    assert bad.status_code == 422 and "unknown class" in bad.json()["error"]


def test_a_new_rule_is_added_at_the_end(client):
    count = len(client.get("/api/knowledge/swrl/rules").json()["rules"])
    text = "Customer(?c), age(?c, ?a), greaterThan(?a, 64) -> needsChildSeat(?c, false)"
    assert client.post("/api/knowledge/swrl/rules/check", json={"text": text}).json()["ok"] is True
    added = client.post("/api/knowledge/swrl/rules", json={"text": text, "comment": "seniors"})
    assert added.status_code == 201, added.text
    assert added.json()["number"] == count + 1 and added.json()["comment"] == "seniors"


def _poured(client: TestClient) -> str:
    run = client.post("/api/workflows/prepare_drinks/run", json={"inputs": {}}).json()
    assert run["status"] == "succeeded", run
    return next(s["params"]["name"] for s in run["steps"] if s["type"] == "module" and s["step_id"] == "pour")


def test_a_value_inferred_by_swrl_reaches_the_workflow(client):
    """Table 2 #16 on the running gateway: the drink-preparation workflow pours what the rule infers."""
    assert _poured(client) == "pour green tea x 2, 140 ml each"
    pour = client.get("/api/knowledge/swrl/rules/7").json()["text"]
    assert client.put("/api/knowledge/swrl/rules/7", json={"text": pour.replace("0.8", "0.7")}).status_code == 200
    assert _poured(client) == "pour green tea x 2, 122.5 ml each"


def test_a_string_value_is_quoted_and_escaped_in_the_turtle(client, gateway):
    answer = client.put("/api/knowledge/individuals/table4/values/locationId", json={"value": 'table "4" b'})
    assert answer.status_code == 200, answer.text
    assert gateway.knowledge.value("table4.locationId") == 'table "4" b'
    assert 'printeps:locationId "table \\"4\\" b"' in client.get("/api/knowledge/ontology").json()["text"]
