"""REST: a rule set's outline (GET/POST /api/rulesets/{name}/outline): its rules by name with their
sentences and positions, decision-table rows labelled, and what feeds the rule set."""

from __future__ import annotations

import sys
from pathlib import Path

from gateway.engine.ruleset import read_folder

sys.path.insert(0, str(Path(__file__).resolve().parent))

from test_authoring import table_files  # noqa: E402

RULES = Path(__file__).resolve().parents[2] / "rules" / "drl"


def test_the_dslr_rules_with_their_sentences_and_lines(client):
    files = read_folder(RULES / "reception")
    body = client.post("/api/rulesets/reception/outline", json={"files": files}).json()
    by_name = {r["name"]: r for r in body["rules"]}
    assert len(by_name) == 32
    pair = by_name["Greet a pair"]
    assert pair["file"] == "reception.dslr"
    assert files["reception.dslr"].split("\n")[pair["line"] - 1] == 'rule "Greet a pair"'
    assert 'Pepper says "Welcome. Two seats?"' in pair["then"] and "- of exactly 2 customers" in pair["when"]
    assert not any(s.startswith("salience") for s in pair["when"] + pair["then"])
    kinds = {u["kind"] for u in body["used_by"]}
    assert "query" in kinds or "ros" in kinds, body["used_by"]
    assert any("fire_business_rules" in u["text"] for u in body["used_by"])


def test_a_table_row_in_the_owners_words_and_the_live_outline(client):
    files = table_files()
    assert client.put("/api/rulesets/dt-outline", json={"files": files}).status_code == 201
    body = client.get("/api/rulesets/dt-outline/outline").json()
    pair = next(r for r in body["rules"] if r["name"] == "Greet a pair")
    assert pair["file"] == "greetings.xlsx" and pair["row"] > 0
    assert "Welcome. Two seats?" in pair["when"][0]
    assert body["used_by"] == []  # nothing feeds a rule set made here
    assert client.get("/api/rulesets/no-such-set/outline").status_code == 404
