"""REST: test scenarios (POST /api/rulesets/{name}/test, the deploy gate) and decision tables
(.xlsx files written by openpyxl travelling as data: URLs, grids for the workbench)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "engine"))

from authoring_samples import files_with, group, table_rows, xlsx_text  # noqa: E402

SCENARIOS = """\
- name: a pair is welcomed
  given:
    - {type: Group, entrance: front, kind: pair, size: 2}
  expect:
    fired: [Greet a pair]
    actions:
      - {module: say, params: {text: "Welcome. Two seats?"}}
- name: anyone else is welcomed too
  given:
    - {type: Group, entrance: front, kind: friends, size: 3}
  expect:
    fired: [Greet anyone]
"""


def table_files(**changes: str) -> dict[str, str]:
    """The greetings table (an .xlsx written by openpyxl) with its scenarios; ``E11="Hi!"`` changes a cell."""
    rows = table_rows()
    for ref, value in changes.items():
        rows[int(ref[1:]) - 1][ord(ref[0]) - ord("A")] = value
    return {**files_with("greetings.xlsx", _xlsx(rows)), "tests/greetings.yaml": SCENARIOS}


def _xlsx(rows: list[list[str]]) -> str:
    import io

    import openpyxl

    from gateway.engine.ruleset import encode_binary

    wb = openpyxl.Workbook()
    ws = wb.active
    ws.title = "Greetings"
    for r, row in enumerate(rows, start=1):
        for c, value in enumerate(row, start=1):
            if value != "":
                ws.cell(r, c, value)
    ws.merge_cells("C8:D8")
    buffer = io.BytesIO()
    wb.save(buffer)
    return encode_binary(buffer.getvalue())


def said(body: dict) -> list[str]:
    return [a["params"]["text"] for a in body["actions"] if a["module"] == "say"]


def test_an_xlsx_table_deploys_fires_and_comes_back_unchanged(client):
    files = table_files()
    r = client.put("/api/rulesets/dt-rest", json={"files": files, "comment": "a table"})
    assert r.status_code == 201, r.text
    assert said(client.post("/api/rulesets/dt-rest/fire", json={"facts": [group("pair", 2)]}).json()) == ["Welcome. Two seats?"]
    got = client.get("/api/rulesets/dt-rest").json()["files"]
    assert got == files and got["greetings.xlsx"].startswith("data:application/vnd.openxmlformats")
    expanded = client.post("/api/rulesets/dt-rest/expand", json={"files": files}).json()["expanded"]
    assert 'rule "Greet a pair"' in expanded["greetings.xlsx"]


def test_table_errors_name_sheet_and_cell_and_deploy_nothing(client):
    client.put("/api/rulesets/dt-bad", json={"files": table_files()})
    bad = table_files(F11="soon")
    r = client.put("/api/rulesets/dt-bad", json={"files": bad})
    assert r.status_code == 422
    error = r.json()["errors"][0]
    assert error == {"file": "greetings.xlsx", "line": 11, "column": 6, "sheet": "Greetings", "cell": "F11",
                     "message": "PRIORITY must be a whole number, not 'soon'"}
    assert client.get("/api/rulesets/dt-bad/versions").json()[-1]["version"] == 1
    v = client.post("/api/rulesets/dt-bad/validate", json={"files": bad}).json()
    assert v["ok"] is False and v["errors"][0]["cell"] == "F11"
    # A workbook that is not a data: URL, or not a workbook at all, is refused naming the file.
    r = client.post("/api/rulesets/dt-bad/validate", json={"files": {**bad, "greetings.xlsx": "PK\u0003\u0004"}})
    assert r.json()["errors"][0]["file"] == "greetings.xlsx" and "data: URL" in r.json()["errors"][0]["message"]


def test_scenarios_run_on_drafts_versions_and_the_current_version(client):
    files = table_files()
    client.put("/api/rulesets/dt-tests", json={"files": files})
    current = client.post("/api/rulesets/dt-tests/test").json()
    assert current["ok"] is True and current["version"] == 1 and current["passed"] == 2
    assert current["coverage"] == {"rules": 3, "fired": ["Greet a pair", "Greet anyone"], "not_fired": ["Greet a family"]}
    draft = dict(files, **{"greetings.xlsx": table_files(E11="Hi!")["greetings.xlsx"]})
    red = client.post("/api/rulesets/dt-tests/test", json={"files": draft}).json()
    assert red["ok"] is False and red["version"] is None and (red["passed"], red["failed"]) == (1, 1)
    result = red["results"][0]
    assert result["status"] == "failed" and result["line"] == 1
    assert result["failures"] == [{"line": 7, "message": 'expected action say {text: "Welcome. Two seats?"} was not '
                                               "requested; closest: say {robot: pepper, text: \"Hi!\"} (from rule 'Greet a pair')"}]
    assert result["actual"]["fired"] == ["Greet a pair"] and result["expected"]["fired"] == ["Greet a pair"]
    by_version = client.post("/api/rulesets/dt-tests/test", json={"version": 1}).json()
    assert by_version["ok"] is True
    assert client.post("/api/rulesets/dt-tests/test", json={"version": 9}).status_code == 404
    assert client.post("/api/rulesets/dt-tests/test", json={"files": files, "version": 1}).status_code == 422


def test_malformed_scenarios_and_broken_rules_are_422_with_positions(client):
    files = table_files()
    r = client.post("/api/rulesets/dt-tests/test", json={"files": {**files, "tests/greetings.yaml": "- name: x\n  expect: [\n"}})
    assert r.status_code == 422
    assert r.json()["errors"][0]["file"] == "tests/greetings.yaml" and r.json()["errors"][0]["line"] == 3
    r = client.put("/api/rulesets/dt-malformed", json={"files": {**files, "tests/greetings.yaml": "- name: x\n"}})
    assert r.status_code == 422 and client.get("/api/rulesets/dt-malformed").status_code == 404
    bad_name = client.post("/api/rulesets/dt-tests/validate", json={"files": {**files, "tests/../x.yaml": "[]"}})
    assert bad_name.json()["errors"][0]["message"].startswith("invalid file name")


def test_a_red_deploy_is_refused_unless_forced(client):
    files = table_files()
    assert client.put("/api/rulesets/dt-gate", json={"files": files}).status_code == 201
    red = dict(files, **{"greetings.xlsx": table_files(E11="Hi!")["greetings.xlsx"]})
    r = client.put("/api/rulesets/dt-gate", json={"files": red, "comment": "new words"})
    assert r.status_code == 422
    body = r.json()
    assert body["kind"] == "scenarios" and body["error"].startswith("not deployed: 1 of 2 scenarios are red")
    assert body["errors"] == [{"file": "tests/greetings.yaml", "line": 7, "column": 1,
                               "message": "scenario 'a pair is welcomed': expected action say {text: \"Welcome. Two seats?\"} "
                                          "was not requested; closest: say {robot: pepper, text: \"Hi!\"} (from rule 'Greet a pair')"}]
    assert body["report"]["failed"] == 1
    assert said(client.post("/api/rulesets/dt-gate/fire", json={"facts": [group("pair", 2)]}).json()) == ["Welcome. Two seats?"]
    forced = client.put("/api/rulesets/dt-gate", json={"files": red, "comment": "new words", "force": True})
    assert forced.status_code == 201 and forced.json()["version"] == 2
    assert said(client.post("/api/rulesets/dt-gate/fire", json={"facts": [group("pair", 2)]}).json()) == ["Hi!"]


def test_decision_table_grids(client):
    text = xlsx_text()
    grid = client.post("/api/decision-tables/read", json={"file": "g.xlsx", "content": text}).json()
    rows = grid["sheets"][0]["rows"]
    assert grid["table_sheet"] == "Greetings" and rows[10][4] == "Welcome. Two seats?"
    rows[10][4] = "Hello there"
    written = client.post("/api/decision-tables/write",
                          json={"file": "g.xlsx", "content": text, "sheet": "Greetings", "rows": rows}).json()
    again = client.post("/api/decision-tables/read", json={"file": "g.xlsx", "content": written["content"]}).json()
    assert again["sheets"][0]["rows"][10][4] == "Hello there" and again["sheets"][0]["merged"] == ["C8:D8"]
    r = client.post("/api/decision-tables/read", json={"file": "g.xlsx", "content": "not a workbook"})
    assert r.status_code == 422 and "data: URL" in r.json()["error"]
    r = client.post("/api/decision-tables/read", json={"file": "g.drl", "content": ""})
    assert r.status_code == 422 and "not a decision table file" in r.json()["error"]
    r = client.post("/api/decision-tables/write", json={"file": "g.xlsx", "content": text, "sheet": "Nope", "rows": []})
    assert r.status_code == 422 and "no sheet named 'Nope'" in r.json()["error"]


def test_authoring_routes_need_a_token(secured):
    assert secured.post("/api/rulesets/dt-gate/test").status_code == 401
    ok = secured.post("/api/rulesets/dt-gate/test", headers={"Authorization": "Bearer tok-caller"})
    assert ok.status_code == 200
    assert secured.post("/api/decision-tables/read", json={"file": "a.csv", "content": ""}).status_code == 401
