"""Rule test scenarios (tests/*.yaml): malformed files are refused at their line, scenarios run on the
real engine with expected-against-actual reports, coverage and JUnit XML, and the shipped reception
scenarios cover all 32 rules."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import pytest

from gateway.config import PROJECT_ROOT, Settings
from gateway.engine import CompileFailed, Engine
from gateway.engine import scenario_files, scenarios
from gateway.engine.ruleset import read_folder

from authoring_samples import files_with, xlsx_text

GOOD = """\
- name: a pair is welcomed
  given:
    - {type: Group, entrance: front, kind: pair, size: 2}
  expect:
    fired: [Greet a pair]
    not_fired: [Greet anyone]
    actions:
      - {module: say, params: {text: "Welcome. Two seats?"}}
    no_other_actions: true
    facts:
      - {type: Group, kind: pair}

- name: a family is welcomed once
  given:
    - {type: Group, entrance: side, kind: family, size: 4}
  expect:
    fired: {Greet a family: 1, Greet a pair: 0}
    actions:
      - {module: say, params: {robot: pepper}}
"""


@pytest.fixture(scope="module")
def engine(tmp_path_factory) -> Engine:
    return Engine(Settings(data_dir=str(tmp_path_factory.mktemp("scenario-data"))))


def rule_set(tests: str, name: str = "tests/greetings.yaml") -> dict[str, str]:
    return {**files_with("greetings.xlsx", xlsx_text()), name: tests}


# --------------------------------------------------------------------------- malformed files


@pytest.mark.parametrize("text, line, column, message", [
    ("- name: a\n  given: [\n", 3, 1, "not valid YAML"),
    ("name: a\n", 1, 1, "a scenario file is a list of scenarios"),
    ("- name: a\n  exepct: {fired: [X]}\n", 2, 3, "unknown key 'exepct' in a scenario (did you mean 'expect'?)"),
    ("- name: a\n  expect: {fired: [X]}\n  expect: {fired: [Y]}\n", 3, 3, "duplicate key 'expect'"),
    ("- given: []\n  expect: {fired: [X]}\n", 1, 3, "a scenario needs a 'name'"),
    ("- name: a\n  given:\n    - {id: c1}\n  expect: {fired: [X]}\n", 3, 7, "fact 1 of 'given' must be a mapping with a 'type'"),
    ("- name: a\n  given: []\n", 1, 3, "scenario 'a' has no 'expect'"),
    ("- name: a\n  expect: {}\n", 2, 11, "'expect' is empty"),
    ("- name: a\n  expect:\n    actions:\n      - {params: {text: hi}}\n", 4, 9, "action 1 must be a mapping with a 'module'"),
    ("- name: a\n  expect:\n    fired: {X: many}\n", 3, 16, "the count for 'X' must be a whole number"),
    ("- name: a\n  expect:\n    fired: [X]\n    not_fired: [X]\n", 4, 17, "'X' is in both 'fired' and 'not_fired'"),
    ("- name: a\n  expect:\n    no_other_actions: yes please\n", 3, 23, "'no_other_actions' must be true or false"),
])
def test_malformed_scenario_files_name_file_line_and_column(text, line, column, message):
    errors = scenario_files.format_errors({"tests/bad.yaml": text})
    assert errors, text
    first = errors[0]
    assert (first.file, first.line, first.column) == ("tests/bad.yaml", line, column), first
    assert message in first.message


def test_names_are_unique_across_files():
    errors = scenario_files.format_errors({"tests/a.yaml": GOOD, "tests/b.yaml": "- name: a pair is welcomed\n  expect: {fired: [X]}\n"})
    assert [(e.file, e.line) for e in errors] == [("tests/b.yaml", 1)]
    assert "the first is at tests/a.yaml:1" in errors[0].message


def test_a_malformed_scenario_file_deploys_nothing(engine):
    engine.deploy("guarded", rule_set(GOOD))
    with pytest.raises(CompileFailed) as failed:
        engine.deploy("guarded", rule_set(GOOD.replace("  expect:\n    fired: [Greet a pair]", "  expect:\n    fired: [Greet a pair\n", 1)))
    assert failed.value.errors[0].file == "tests/greetings.yaml" and failed.value.errors[0].line > 0
    assert engine.current("guarded").info.version == 1
    assert engine.validate("guarded", rule_set("- name: x\n")) [0].message == "scenario 'x' has no 'expect': say what must happen"


# --------------------------------------------------------------------------- running


def test_green_scenarios_report_expected_actual_and_coverage(engine):
    report = scenarios.run_scenarios(engine, rule_set(GOOD), "greetings")
    assert report.ok and report.counts == {"scenarios": 2, "passed": 2, "failed": 0, "errors": 0}
    assert report.rules == ["Greet a family", "Greet a pair", "Greet anyone"]
    assert report.uncovered == ["Greet anyone"]
    body = report.to_dict()
    first = body["results"][0]
    assert (first["file"], first["line"], first["status"]) == ("tests/greetings.yaml", 1, "passed")
    assert first["actual"]["fired"] == ["Greet a pair"]
    assert first["actual"]["actions"][0]["params"]["text"] == "Welcome. Two seats?"
    assert first["expected"]["no_other_actions"] is True
    assert body["coverage"] == {"rules": 3, "fired": ["Greet a family", "Greet a pair"], "not_fired": ["Greet anyone"]}


RED = """\
- name: wrong words
  given:
    - {type: Group, entrance: front, kind: pair, size: 2}
  expect:
    fired: [Greet a pear]
    not_fired: [Greet a pair]
    actions:
      - {module: say, params: {text: "Hello, you two"}}
      - {module: move, params: {location: window}}
- name: counts and extras
  given:
    - {type: Group, entrance: front, kind: pair, size: 2}
    - {type: Group, entrance: side, kind: family, size: 3}
  expect:
    fired: {Greet a pair: 2}
    no_other_actions: true
    facts:
      - {type: Group, kind: couple}
- name: order matters when asked
  given:
    - {type: Group, entrance: front, kind: pair, size: 2}
  expect:
    ordered: true
    actions:
      - {module: say}
      - {module: say}
- name: refused facts
  given:
    - {type: Group, kind: pair, size: 2}
    - {type: Group, kind: pair, size: two}
  expect:
    fired: [Greet a pair]
"""


def test_red_scenarios_say_what_differs_and_where(engine):
    report = scenarios.run_scenarios(engine, rule_set(RED), "greetings")
    assert not report.ok
    assert [r.status for r in report.results] == ["failed", "failed", "failed", "error"]
    wrong, counts, order, refused = report.results
    messages = [(f.line, f.message) for f in wrong.failures]
    assert messages == [
        (5, "there is no rule named 'Greet a pear' (did you mean 'Greet a pair'?)"),
        (6, "rule 'Greet a pair' fired, but must not"),
        (8, 'expected action say {text: "Hello, you two"} was not requested; closest: '
            'say {robot: pepper, text: "Welcome. Two seats?"} (from rule \'Greet a pair\')'),
        (9, "expected action move {location: window} was not requested"),
    ]
    assert [f.message for f in counts.failures] == [
        "rule 'Greet a pair' fired 1 times, expected 2",
        '1 action(s) beyond those expected: say {robot: pepper, text: "Welcome. Two seats?"}',
        "no fact matches Group {kind: couple} (Group facts: Group {entrance: front, kind: pair, size: 2}; "
        "Group {entrance: side, kind: family, size: 3})",
    ]
    assert order.failures[0].message.startswith("expected action say {} was not requested")
    assert refused.failures[0].line == 30  # the refused fact's own line
    assert "field 'size'" in refused.failures[0].message
    problems = report.problems()
    assert str(problems[0]) == ("tests/greetings.yaml:5:1: scenario 'wrong words': there is no rule named "
                                "'Greet a pear' (did you mean 'Greet a pair'?)")


def test_junit_xml_and_text_report(engine):
    report = scenarios.run_scenarios(engine, rule_set(RED + GOOD.replace("- name: a", "- name: b")), "greetings")
    root = ET.fromstring(report.junit_xml())
    assert root.tag == "testsuites" and root.get("tests") == "6" and root.get("failures") == "3" and root.get("errors") == "1"
    suite = root.find("testsuite")
    assert suite.get("name") == "greetings/tests/greetings.yaml"
    cases = suite.findall("testcase")
    assert [c.get("line") for c in cases][:2] == ["1", "10"]
    assert cases[0].find("failure").get("message").startswith("there is no rule named 'Greet a pear'")
    assert cases[3].find("error") is not None and cases[4].find("failure") is None
    lines = scenarios.text_report(report.to_dict(), "rules/greetings")
    assert "  ✗ wrong words  (rules/greetings/tests/greetings.yaml:1)" in lines
    assert any(line.startswith("      rules/greetings/tests/greetings.yaml:5: there is no rule") for line in lines)
    assert lines[-1] == "greetings: 6 scenarios: 2 passed, 3 failed, 1 with errors"


def test_no_scenarios_is_green(engine):
    report = scenarios.run_scenarios(engine, files_with("greetings.xlsx", xlsx_text()), "greetings")
    assert report.ok and report.results == [] and report.summary().startswith("no scenarios")


def test_the_reception_scenarios_pass_and_fire_all_32_rules(engine):
    files = read_folder(PROJECT_ROOT / "rules" / "drl" / "reception")
    assert "tests/reception.yaml" in files
    report = scenarios.run_scenarios(engine, files, "reception")
    assert [r.scenario.name for r in report.red()] == []
    assert len(report.rules) == 32 and report.uncovered == []


def test_the_greetings_table_scenarios_pass_and_cover_every_row(engine):
    files = read_folder(PROJECT_ROOT / "rules" / "drl" / "reception_greetings")
    report = scenarios.run_scenarios(engine, files, "reception_greetings")
    assert report.ok and report.uncovered == [] and len(report.rules) == 14
