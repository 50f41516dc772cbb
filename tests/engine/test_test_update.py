"""Update the tests too, beyond a changed sentence (issue 31): an expected fact's value the draft
changed and a rule the draft renamed are followed in the test file, at their line, layout kept;
an ambiguous rename, a deleted rule or a fact wrong for another reason stays red and untouched.
On the real engine (the scenarios are run, not simulated)."""

from __future__ import annotations

import pytest

from gateway.config import Settings
from gateway.engine import Engine
from gateway.engine.scenarios import run_scenarios
from gateway.engine.test_update import renames, rule_texts, update_tests

TYPES = """package org.printeps.upd;
import org.printeps.gateway.Actions;
global Actions actions;

declare Party
    id: String
    size: int
end

declare Seat
    party: String
    place: String
end
"""

RULES = """package org.printeps.upd;

rule "Greet a pair"
when
    $p: Party(size == 2)
then
    actions.say("pepper", "Welcome. Two seats?");
    insert(new Seat($p.getId(), "window"));
end

rule "Greet a group"
when
    Party(size > 2)
then
    actions.say("pepper", "Welcome, all of you.");
end
"""

TESTS = """# How the door greets (a comment the update keeps)

- name: a pair gets the window
  given:
    - {type: Party, id: p1, size: 2}
  expect:
    fired: [Greet a pair]          # the pair rule decides
    facts:
      - {type: Seat, party: p1, place: window}

- name: a group is not a pair
  given:
    - {type: Party, id: p2, size: 4}
  expect:
    fired: {Greet a group: 1}
    not_fired:
      - Greet a pair
"""


@pytest.fixture(scope="module")
def engine(tmp_path_factory) -> Engine:
    return Engine(Settings(data_dir=str(tmp_path_factory.mktemp("update-data"))))


def live() -> dict[str, str]:
    return {"types.drl": TYPES, "rules.drl": RULES, "tests/door.yaml": TESTS}


def draft(*edits: tuple[str, str]) -> dict[str, str]:
    files = live()
    for old, new in edits:
        assert old in files["rules.drl"], old
        files["rules.drl"] = files["rules.drl"].replace(old, new)
    return files


def red(engine: Engine, files: dict[str, str]) -> list[str]:
    return [r.scenario.name for r in run_scenarios(engine, files).red()]


def test_the_live_rules_pass_their_tests(engine):
    assert red(engine, live()) == []


def test_a_changed_fact_value_is_followed_at_its_line(engine):
    files = draft(('"window"', '"garden"'))
    assert red(engine, files) == ["a pair gets the window"]
    body = update_tests(engine, files, "door", live())
    assert body["changes"] == [{"scenario": "a pair gets the window", "file": "tests/door.yaml", "line": 9,
                                "old": "window", "new": "garden", "rule": None, "what": "fact"}]
    assert body["kept"] == []
    updated = body["files"]["tests/door.yaml"]
    assert updated == TESTS.replace("place: window}", "place: garden}")
    assert red(engine, {**files, **body["files"]}) == []


def test_a_renamed_rule_is_followed_in_fired_and_not_fired(engine):
    files = draft(('rule "Greet a pair"', 'rule "Welcome a pair"'))
    assert red(engine, files) == ["a pair gets the window", "a group is not a pair"]
    body = update_tests(engine, files, "door", live())
    assert [(c["scenario"], c["line"], c["old"], c["new"], c["what"]) for c in body["changes"]] == [
        ("a pair gets the window", 7, "Greet a pair", "Welcome a pair", "rule"),
        ("a group is not a pair", 17, "Greet a pair", "Welcome a pair", "rule")]
    updated = body["files"]["tests/door.yaml"]
    assert "    fired: [Welcome a pair]          # the pair rule decides\n" in updated
    assert "      - Welcome a pair\n" in updated
    assert updated.startswith("# How the door greets (a comment the update keeps)\n")
    assert red(engine, {**files, **body["files"]}) == []


def test_a_rename_and_a_changed_value_together(engine):
    files = draft(('rule "Greet a pair"', 'rule "Welcome a pair"'), ('"window"', '"garden"'))
    body = update_tests(engine, files, "door", live())
    assert {(c["what"], c["old"], c["new"]) for c in body["changes"]} == {
        ("rule", "Greet a pair", "Welcome a pair"), ("fact", "window", "garden")}
    assert red(engine, {**files, **body["files"]}) == []


def test_an_ambiguous_rename_or_a_deleted_rule_stays_red(engine):
    # "Greet a pair" gone, two new rules, neither with its text: which one is it? Nothing is guessed.
    two_new = draft(('rule "Greet a pair"', 'rule "Welcome a pair"'), ('"window"', '"garden"'),
                    ('rule "Greet a group"', 'rule "Welcome a crowd"\nwhen\n    Party(size > 9)\nthen\n    '
                     'actions.say("pepper", "Hello!");\nend\n\nrule "Greet a group"'))
    body = update_tests(engine, two_new, "door", live())
    assert body["changes"] == [] and body["files"] == {}
    assert body["kept"] == ["a pair gets the window", "a group is not a pair"]

    gone = live()
    gone["rules.drl"] = RULES[:RULES.index('rule "Greet a pair"')] + RULES[RULES.index('rule "Greet a group"'):]
    body = update_tests(engine, gone, "door", live())
    assert body["changes"] == [] and len(body["kept"]) == 2


def test_a_fact_wrong_for_another_reason_stays_red(engine):
    """The expected place was never in the rules (a typo in the test): no draft change explains it."""
    files = live()
    files["tests/door.yaml"] = TESTS.replace("place: window}", "place: windwo}")
    body = update_tests(engine, files, "door", live())
    assert body == {"files": {}, "changes": [], "kept": ["a pair gets the window"]}


def test_renames_pair_rules_by_their_text_when_several_change():
    base = RULES
    both = RULES.replace('rule "Greet a pair"', 'rule "Pair"').replace('rule "Greet a group"', 'rule "Group"')
    assert renames(base, both, ["Pair", "Group"]) == {"Greet a pair": "Pair", "Greet a group": "Group"}
    assert set(rule_texts(base)) == {"Greet a pair", "Greet a group"}
    twins = base + '\nrule "Greet a pair again"\nwhen\n    $p: Party(size == 2)\nthen\n' \
        '    actions.say("pepper", "Welcome. Two seats?");\n    insert(new Seat($p.getId(), "window"));\nend\n'
    renamed_twins = twins.replace('rule "Greet a pair"\n', 'rule "P1"\n')
    renamed_twins = renamed_twins.replace('rule "Greet a pair again"', 'rule "P2"')
    assert renames(twins, renamed_twins, ["P1", "Greet a group", "P2"]) == {}  # two identical rules: ambiguous
