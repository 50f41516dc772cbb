"""The shipped dialogue rule set: it compiles, all its test scenarios are green (a seed is served
even with red scenarios, so this is where a broken sentence is caught), and its sentences make the
recogniser's grammar."""

from __future__ import annotations

from gateway.config import PROJECT_ROOT
from gateway.dialogue.grammar import sentences
from gateway.engine import scenarios
from gateway.engine.ruleset import read_folder

FOLDER = PROJECT_ROOT / "rules" / "drl" / "dialogue"


def test_every_scenario_of_the_dialogue_rules_is_green(gateway):
    files = read_folder(FOLDER)
    report = scenarios.run_scenarios(gateway.engine, files, "dialogue")
    failed = [r.to_dict() for r in report.results if not r.passed]
    assert report.ok and not failed, failed
    assert report.counts["passed"] >= 20


def test_the_sentences_are_read_from_the_rules():
    meaning, fillers = sentences(read_folder(FOLDER))
    assert "NUMBER DRINK" in meaning and "no make that DRINK" in meaning and "yes" in meaning
    assert "please" in fillers and "can i have" in fillers and "please" not in meaning
