"""shared_patterns: what the request-join network needs to know of all a set's plain rules at once
(which first patterns open several rules, which rules open as an auto-focus rule does). Pure Python,
on rule descriptions of the shape plain_rules.describe gives; the networks themselves are checked
in test_request_joins.py."""

from __future__ import annotations

import json
import uuid

from gateway.engine import shared_patterns


def pattern(type_: str, constraints: list, var: str | None = None, binds: list | None = None) -> dict:
    return {"pattern": {"type": type_, "constraints": constraints, "var": var, "binds": binds or []}}


PERSON_N = [{"field": "region", "op": "==", "literal": "n"}]
LOAN_JOIN = [{"field": "applicant", "op": "==", "ref": "$id"}]


def rule(name: str, *lhs: dict, auto_focus: bool = False) -> dict:
    return {"name": name, "lhs": list(lhs), **({"attributes": {"auto-focus": True}} if auto_focus else {})}


def mark_shared(units: list[dict]) -> list[list[int]]:
    """Marks ``units`` (descriptions) as a deploy does: each unit's shapes read under its id, the
    marks of all units, each unit's description with its marks; returns the marked positions."""
    data = [json.dumps(unit).encode() for unit in units]
    unit_marks = shared_patterns.marks([shared_patterns.unit_shapes(uuid.uuid4().hex, d) for d in data])
    for unit, one, marks in zip(units, data, unit_marks):
        if marks:
            for rule_, marked in zip(unit["rules"], json.loads(shared_patterns.with_marks(one, marks))["rules"]):
                rule_.update(marked)
    return [sorted(marks) for marks in unit_marks]


def test_a_unit_is_read_once_under_its_id():
    unit = json.dumps({"rules": [rule("a", pattern("Person", PERSON_N))]}).encode()
    shapes = shared_patterns.unit_shapes("unit-read-once", unit)
    assert shared_patterns.unit_shapes("unit-read-once", b"not read again") is shapes


def test_a_first_pattern_that_opens_two_rules_is_marked_in_every_unit():
    one = {"rules": [rule("a", pattern("Person", PERSON_N, "$p")), rule("b", pattern("Person", [], "$p"))]}
    two = {"rules": [rule("c", pattern("org.x.Person", PERSON_N, "$q", [{"name": "$id"}]), pattern("Loan", LOAN_JOIN))]}
    assert mark_shared([one, two]) == [[0], [0]]
    assert one["rules"][0]["firstShared"] and two["rules"][0]["firstShared"]
    assert "firstShared" not in one["rules"][1]


def test_a_rule_that_opens_as_an_auto_focus_rule_gets_its_guards():
    focused = rule("f", pattern("Person", PERSON_N, "$p"), pattern("Loan", LOAN_JOIN, "$l"), auto_focus=True)
    alike = rule("g", pattern("Person", PERSON_N, "$a"), pattern("Loan", LOAN_JOIN, "$m"), pattern("Loan", []))
    otherwise = rule("h", pattern("Person", PERSON_N, "$p"), pattern("Loan", []))
    units = [{"rules": [focused, alike, otherwise]}]
    mark_shared(units)
    assert alike["guardedPrefix"] == 2  # the names bound aside, it opens as "f" for two elements
    assert "guardedPrefix" not in otherwise and "guardedPrefix" not in focused
    assert all(r["firstShared"] for r in units[0]["rules"])


def test_a_rule_that_shares_an_exists_with_an_auto_focus_rule_is_guarded_in_another_unit():
    exists = {"exists": {"type": "Loan", "constraints": LOAN_JOIN, "binds": []}}
    focused = rule("f", pattern("Person", PERSON_N, "$p"), exists, auto_focus=True)
    alike = rule("g", pattern("Person", PERSON_N, "$p"), exists, pattern("Loan", []))
    other = rule("h", pattern("Person", PERSON_N, "$p"), {"not": exists["exists"]})
    assert mark_shared([{"rules": [focused, other]}, {"rules": [alike]}]) == [[0, 1], [0]]
    assert alike["guardedPrefix"] == 2 and alike["firstShared"]
    assert "guardedPrefix" not in other  # a not is no exists


def test_a_rule_whose_first_test_opens_an_auto_focus_rule_is_not_dispatched():
    region_in = {"field": "region", "op": "in", "literals": [{"s": "n"}, {"s": "e"}]}
    older = {"field": "age", "op": ">", "literal": {"n": "40"}}
    focused = rule("f", pattern("Person", [region_in, older]), auto_focus=True)
    alike = rule("g", pattern("org.x.Person", [region_in, {"field": "age", "op": ">", "literal": {"n": "30"}}]))
    other = rule("h", pattern("Person", [older, region_in]))
    assert mark_shared([{"rules": [focused]}, {"rules": [alike, other]}]) == [[], [0]]
    assert alike["firstShared"] and "firstShared" not in other and "firstShared" not in focused


def test_nothing_is_marked_when_no_two_rules_open_alike():
    units = [{"rules": [rule("a", pattern("Person", PERSON_N)), rule("b", pattern("Loan", []))]}]
    assert mark_shared(units) == [[]]
    assert all("firstShared" not in r and "guardedPrefix" not in r for r in units[0]["rules"])
