"""REST: "Update the tests too" (POST /api/rulesets/{name}/tests/update) on the real reception
rule set and on a decision table: only the scenarios a changed sentence broke are rewritten, at
their line, comments and layout kept; a scenario red for another reason stays red; nothing stored."""

from __future__ import annotations

import sys
from pathlib import Path

from gateway.engine.ruleset import read_folder

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "engine"))

from test_authoring import table_files  # noqa: E402

RECEPTION = Path(__file__).resolve().parents[2] / "rules" / "drl" / "reception"
OLD, NEW = "Welcome. Two seats?", "Welcome! A table for two?"
TESTS = "tests/reception.yaml"


def reception_draft() -> tuple[dict[str, str], dict[str, str]]:
    """The live reception files, and a draft in which "Greet a pair" says NEW and one pair
    scenario also expects a wrong table (red for another reason)."""
    files = read_folder(RECEPTION)
    draft = dict(files)
    draft["reception.dslr"] = files["reception.dslr"].replace(f'Pepper says "{OLD}"\n', f'Pepper says "{NEW}"\n')
    assert draft["reception.dslr"].count(NEW) == 1
    scenarios = files[TESTS]
    teen = scenarios.index("- name: teenage boy and girl")
    end = scenarios.index("- name:", teen + 5)
    broken = scenarios[teen:end].replace("location: table for two", "location: table for three")
    draft[TESTS] = scenarios[:teen] + broken + scenarios[end:]
    return files, draft


def test_only_the_changed_sentences_scenarios_are_rewritten_in_place(client):
    files, draft = reception_draft()
    assert client.put("/api/rulesets/rec-upd", json={"files": files, "comment": "start"}).status_code == 201
    before = client.post("/api/rulesets/rec-upd/test", json={"files": draft}).json()
    red = {r["name"] for r in before["results"] if r["status"] != "passed"}
    assert red == {"pair: the papers' greeting", "teenage boy and girl are a pair, not a couple",
                   "Pepper is called from the kitchen first"}

    r = client.post("/api/rulesets/rec-upd/tests/update", json={"files": draft})
    assert r.status_code == 200, r.text
    body = r.json()
    assert {c["scenario"] for c in body["changes"]} == {"pair: the papers' greeting", "Pepper is called from the kitchen first"}
    assert all(c["old"] == OLD and c["new"] == NEW and c["file"] == TESTS and c["rule"] == "Greet a pair"
               for c in body["changes"])
    assert body["kept"] == ["teenage boy and girl are a pair, not a couple"]
    updated = body["files"][TESTS]
    old_lines, new_lines = draft[TESTS].split("\n"), updated.split("\n")
    assert len(old_lines) == len(new_lines)
    differing = [n + 1 for n, (a, b) in enumerate(zip(old_lines, new_lines)) if a != b]
    assert differing == sorted(c["line"] for c in body["changes"])
    for line in differing:
        assert new_lines[line - 1] == old_lines[line - 1].replace(f'"{OLD}"', f'"{NEW}"')
    assert "ordered: true                # Pepper comes to the entrance before she greets" in updated
    assert updated.count(f'"{OLD}"') == 1  # the teenage scenario keeps the old sentence

    after = client.post("/api/rulesets/rec-upd/test", json={"files": {**draft, TESTS: updated}}).json()
    assert [r["name"] for r in after["results"] if r["status"] != "passed"] == ["teenage boy and girl are a pair, not a couple"]
    assert [v["version"] for v in client.get("/api/rulesets/rec-upd/versions").json()] == [1]  # nothing stored


def test_a_changed_table_cell_updates_its_scenario(client):
    files = table_files()
    assert client.put("/api/rulesets/dt-upd", json={"files": files}).status_code == 201
    draft = dict(files, **{"greetings.xlsx": table_files(E11="Hi!")["greetings.xlsx"]})
    body = client.post("/api/rulesets/dt-upd/tests/update", json={"files": draft}).json()
    assert body["changes"] == [{"scenario": "a pair is welcomed", "file": "tests/greetings.yaml", "line": 7,
                                "old": "Welcome. Two seats?", "new": "Hi!", "rule": "Greet a pair", "what": "action"}]
    assert 'params: {text: "Hi!"}' in body["files"]["tests/greetings.yaml"]
    deployed = client.put("/api/rulesets/dt-upd", json={"files": {**draft, **body["files"]}, "comment": "new words"})
    assert deployed.status_code == 201, deployed.text


def test_a_scenario_not_broken_by_the_draft_is_not_rewritten(client):
    """The expected sentence was never in the rules (a typo in the test): no draft change explains it;
    nor is anything rewritten for a rule set with no live version."""
    files = table_files()
    nothing = {"files": {}, "changes": [], "kept": ["a pair is welcomed"]}
    draft = dict(files, **{"greetings.xlsx": table_files(E11="Hi!")["greetings.xlsx"]})
    assert client.post("/api/rulesets/dt-new/tests/update", json={"files": draft}).json() == nothing
    assert client.put("/api/rulesets/dt-typo", json={"files": files}).status_code == 201
    files["tests/greetings.yaml"] = files["tests/greetings.yaml"].replace("Welcome. Two seats?", "Welcome, two seats?")
    body = client.post("/api/rulesets/dt-typo/tests/update", json={"files": files}).json()
    assert body == nothing


def test_a_draft_that_does_not_compile_is_422(client):
    files = table_files()
    files["broken.drl"] = "rule \"x\" when then end end"
    r = client.post("/api/rulesets/dt-upd/tests/update", json={"files": files})
    assert r.status_code == 422 and r.json()["errors"][0]["file"] == "broken.drl"


def test_a_renamed_rule_and_a_changed_fact_value_are_followed(client):
    """The author renames rule "Infant" to "Baby" and its category "infant" to "baby": the scenario
    that pins both follows, at its two lines; no other line of the file changes."""
    files = read_folder(RECEPTION)
    draft = dict(files)
    draft["reception.dslr"] = files["reception.dslr"].replace('rule "Infant"', 'rule "Baby"').replace('"infant"', '"baby"')
    assert client.put("/api/rulesets/rec-rename", json={"files": files, "comment": "start"}).status_code == 201
    before = client.post("/api/rulesets/rec-rename/test", json={"files": draft}).json()
    assert [r["name"] for r in before["results"] if r["status"] != "passed"] == ["age 2 is an infant"]

    body = client.post("/api/rulesets/rec-rename/tests/update", json={"files": draft}).json()
    assert [(c["line"], c["old"], c["new"], c["what"]) for c in body["changes"]] == [
        (16, "Infant", "Baby", "rule"), (18, "infant", "baby", "fact")]
    assert body["kept"] == []
    old_lines, new_lines = files[TESTS].split("\n"), body["files"][TESTS].split("\n")
    assert [n + 1 for n, (a, b) in enumerate(zip(old_lines, new_lines)) if a != b] == [16, 18]
    assert new_lines[15] == "    fired: {Baby: 1}" and new_lines[17] == "      - {type: Customer, id: c1, category: baby}"
    after = client.post("/api/rulesets/rec-rename/test", json={"files": {**draft, **body["files"]}}).json()
    assert after["summary"].startswith("✓") or all(r["status"] == "passed" for r in after["results"])
