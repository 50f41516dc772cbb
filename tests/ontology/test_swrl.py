"""The SWRL rule parser (gateway/ontology/swrl.py) on its own: rules round-trip through their atoms
and through the file edits; every error names its column and atom."""

from __future__ import annotations

import pytest

from gateway.config import PROJECT_ROOT
from gateway.ontology.model import ClassInfo, IndividualInfo, OntologyModel, PropertyInfo
from gateway.ontology.swrl import (RuleInvalid, append_rule, describe, parse_atoms, parse_rule, read_rules,
                                   readable, replace_rule, rule_lines)

TEAHOUSE = (PROJECT_ROOT / "ontology" / "teahouse.swrl").read_text()
MODEL = OntologyModel(
    base="http://printeps.org/teahouse#",
    classes={"Customer": ClassInfo("Customer"), "Table": ClassInfo("Table")},
    properties={"hasAge": PropertyInfo("hasAge", "data", "integer"),
                "needsChildSeat": PropertyInfo("needsChildSeat", "data", "boolean"),
                "sitsAt": PropertyInfo("sitsAt", "object", "Table")},
    individuals={"table1": IndividualInfo("table1", ["Table"])},
)
CHILD = "Customer(?c), hasAge(?c, ?a), lessThan(?a, 7) -> needsChildSeat(?c, true)"


def rebuilt(atoms) -> str:
    return ", ".join(f"{a.name}({', '.join(a.args)})" for a in atoms)


def test_a_rule_parses_into_its_atoms_with_their_columns():
    body, head = parse_rule(CHILD, MODEL)
    assert [(a.name, a.args, a.column) for a in body] == [
        ("Customer", ["?c"], 1), ("hasAge", ["?c", "?a"], 15), ("lessThan", ["?a", "7"], 31)]
    assert [(a.name, a.args, a.column, a.text) for a in head] == [
        ("needsChildSeat", ["?c", "true"], CHILD.index("needs") + 1, "needsChildSeat(?c, true)")]
    for atom in body + head:
        assert CHILD[atom.column - 1:].startswith(atom.text)


@pytest.mark.parametrize("rule", [
    CHILD,
    'Customer(?c) -> sitsAt(?c, table1)',
    'Customer(?c),hasAge(?c,?a),add(?b, ?a, 1.5e2),stringConcat(?s, "a \\"quoted\\" text", ?a) -> hasAge(?c, ?b)',
    'Customer(?c), hasAge(?c, -3) -> needsChildSeat(?c, false)',
])
def test_rules_round_trip_through_their_atoms(rule):
    body, head = parse_rule(rule)
    again = f"{rebuilt(body)} -> {rebuilt(head)}"
    body2, head2 = parse_rule(again)
    assert [(a.name, a.args) for a in body2 + head2] == [(a.name, a.args) for a in body + head]


def test_every_teahouse_rule_parses_and_round_trips_through_the_file_edits():
    rules = read_rules(TEAHOUSE)
    assert rules and all(r.body and r.head for r in rules), [r.text for r in rules if not r.body]
    # replacing each rule by itself rebuilt from its atoms leaves the same rules (and comments)
    text = TEAHOUSE
    for rule in rules:
        text = replace_rule(text, rule.number, f"{rebuilt(rule.body)} -> {rebuilt(rule.head)}")
    again = read_rules(text)
    assert [(r.number, r.comment, [(a.name, a.args) for a in r.body + r.head]) for r in again] == \
        [(r.number, r.comment, [(a.name, a.args) for a in r.body + r.head]) for r in rules]
    appended = read_rules(append_rule(text, CHILD, "children need a seat"))
    assert len(appended) == len(rules) + 1
    assert (appended[-1].text, appended[-1].comment) == (CHILD, "children need a seat")


def test_rule_lines_number_rules_and_keep_the_comment_just_above():
    text = "# first\n# more\nA(?x) -> B(?x)\n\n# orphan\n\nC(?x) -> D(?x)\n"
    assert rule_lines(text) == [(3, "A(?x) -> B(?x)", "first more"), (7, "C(?x) -> D(?x)", "")]
    with pytest.raises(IndexError, match="there is no rule 3 \\(rules 1-2\\)"):
        replace_rule(text, 3, "E(?x) -> F(?x)")


def test_a_rule_said_in_words():
    rule = read_rules(CHILD)[0]
    assert readable(rule, MODEL) == "If ?c is a Customer and ?c has age ?a and ?a < 7, then ?c needs child seat."
    assert describe(rule, MODEL)["concludes"] == ["needsChildSeat"]


@pytest.mark.parametrize("rule, column, message", [
    ("Customer(?c) needsChildSeat(?c, true)", 0, "exactly one '->'"),
    ("Customer(?c) -> B(?c) -> C(?c)", 14, "exactly one '->'"),
    (" -> needsChildSeat(?c, true)", 2, "at least one atom"),
    ("Customer(?c) -> ", 14, "at least one atom"),
    ("Customer(?c), 42 -> Table(?c)", 15, "expected an atom like Name(?x)"),
    ("Customer(?c), hasAge(?c ?a) -> Table(?c)", 25, "expected ',' or ')'"),
    ("Customer(?c), hasAge(?c, ) -> Table(?c)", 26, "expected an argument"),
    ("Customer(?c) Table(?c) -> Table(?c)", 14, "expected ',' between atoms"),
    ("Customer(?c) -> Table(?c", 25, "expected ',' or ')'"),
])
def test_syntax_errors_name_their_column(rule, column, message):
    with pytest.raises(RuleInvalid) as err:
        parse_rule(rule)
    assert message in err.value.message
    assert err.value.column == column, (err.value.column, err.value.message)


@pytest.mark.parametrize("rule, atom, message", [
    ("Customer(?c), Dragon(?c) -> Table(?c)", "Dragon(?c)", "'Dragon' is not a class, property or built-in"),
    ("Customer(?c, ?d) -> Table(?c)", "Customer(?c, ?d)", "Customer takes 1 argument, not 2"),
    ("Customer(?c) -> hasAge(?c)", "hasAge(?c)", "hasAge takes 2 arguments, not 1"),
    ("Customer(?c), hasAge(?c, ?a) -> lessThan(?a, 7)", "lessThan(?a, 7)", "the built-in lessThan cannot be a conclusion"),
    ("Customer(?c) -> sitsAt(?c, table9)", "sitsAt(?c, table9)", "table9 is not a ?variable or an individual"),
    ("Customer(?c) -> hasAge(?c, seven)", "hasAge(?c, seven)", "seven is not a ?variable or a value"),
    ("Customer(?c) -> sitsAt(?c, ?t)", "sitsAt(?c, ?t)", "?t in the conclusion does not appear before '->'"),
])
def test_vocabulary_errors_name_the_atom_and_its_column(rule, atom, message):
    with pytest.raises(RuleInvalid) as err:
        parse_rule(rule, MODEL)
    assert message in err.value.message
    assert err.value.atom == atom
    assert rule[err.value.column - 1:].startswith(atom)


def test_parse_atoms_offsets_columns_into_the_whole_rule():
    atoms = parse_atoms("Table(?t)", offset=10)
    assert atoms[0].column == 11
    with pytest.raises(RuleInvalid) as err:
        parse_atoms("Table(?t) (", offset=10)
    assert err.value.column == 21


def test_a_rule_that_does_not_parse_is_kept_with_no_atoms():
    rules = read_rules("A(?x) -> B(?x)\nbroken rule\n")
    assert [(r.number, bool(r.body)) for r in rules] == [(1, True), (2, False)]
    assert readable(rules[1]) == "broken rule"
