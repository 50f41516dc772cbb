"""Which rules are of the plain shapes (built at run time without code generation) and how they are
described. Unit tests: no JVM (the builds themselves are in test_incremental.py)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from gateway.engine import plain_rules
from gateway.engine.drl_items import Item, SourceItems

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench" / "peers"))
import growth_rules


def describe(rule: str, package: str = "p") -> dict | None:
    src = SourceItems("a.drl", package, rule, [Item("rule", "r", 0, len(rule), 1)])
    return plain_rules.describe(src, src.items[0], ["org.example.Thing"])


def test_every_growth_shape_is_plain_and_described_exactly():
    for i in range(5):
        assert describe(growth_rules.rule_drl(i)) is not None, growth_rules.kind(i)
    spec = describe(growth_rules.rule_drl(4))  # the accumulate
    customer, accumulate = spec["lhs"]
    assert customer["pattern"]["var"] == "$c" and customer["pattern"]["type"] == "Customer"
    acc = accumulate["accumulate"]
    assert (acc["function"], acc["arg"], acc["var"]) == ("sum", "$a", "$t")
    assert acc["source"]["binds"] == [{"var": "$a", "field": "amount"}]
    assert acc["source"]["constraints"][0] == {"field": "customer", "op": "==", "ref": "$c", "refField": "id",
                                               "text": "customer == $c.id"}
    assert acc["constraints"][0]["op"] == ">" and "n" in acc["constraints"][0]["literal"]
    assert spec["rhs"] == [{"target": "actions", "method": "say",
                            "args": [{"s": "bot"}, {"s": growth_rules.rule_name(4)}]}]
    assert spec["imports"] == ["org.example.Thing"] and spec["salience"] is None


def test_literals_salience_comments_and_several_calls():
    spec = describe("""rule "x" salience -3
    when
        // a comment
        $o: org.example.Order(total >= -2.5, open == true, code != "A b") /* another */
    then
        actions.say("bot", "one"); actions.count(2);
    end""")
    assert spec["salience"] == -3
    constraints = spec["lhs"][0]["pattern"]["constraints"]
    assert [c["literal"] for c in constraints] == [{"n": "-2.5"}, {"b": True}, {"s": "A b"}]
    assert spec["lhs"][0]["pattern"]["type"] == "org.example.Order"
    assert [c["method"] for c in spec["rhs"]] == ["say", "count"]
    json.loads(plain_rules.spec_json([spec]))  # what a plain unit caches


def test_then_part_arguments_may_read_bound_facts():
    spec = describe('rule "x"\nwhen\n    $o: Order()\nthen\n'
                    '    actions.call("a", $o, $o.getId(), "total " + $o.getTotal() + " of " + $o.isOpen() + 2);\nend')
    assert spec["rhs"][0]["args"] == [
        {"s": "a"}, {"var": "$o"}, {"var": "$o", "getter": "getId"},
        {"concat": [{"s": "total "}, {"var": "$o", "getter": "getTotal"}, {"s": " of "},
                    {"var": "$o", "getter": "isOpen"}, {"n": "2"}]}]


@pytest.mark.parametrize("when, then", [
    ("Order() from $orders", 'actions.say("a", "b");'),
    ("eval(true)", 'actions.say("a", "b");'),
    ("Order(total > 1 && total < 5)", 'actions.say("a", "b");'),
    ("Order(total > 1 || total < 5)", 'actions.say("a", "b");'),
    ("Order(getTotal() > 1)", 'actions.say("a", "b");'),
    ("$o: Order()\n Line(order == $o)", 'actions.say("a", "b");'),  # a fact, not a bound field
    ("$o: Order($t: total > 1)", 'actions.say("a", "b");'),
    ("not $o: Order()", 'actions.say("a", "b");'),
    ("exists Order($t: total)", 'actions.say("a", "b");'),
    ("not (Order() or Line())", 'actions.say("a", "b");'),
    ("Order(code matches $pattern)", 'actions.say("a", "b");'),
    ("Order(code in ($a, $b))", 'actions.say("a", "b");'),
    ("Number() from accumulate(Order($v: total), sum($v * 2))", 'actions.say("a", "b");'),
    ("Number(intValue > $x) from accumulate(Order(), count(1))", 'actions.say("a", "b");'),
    ("$n: Number() from accumulate(Order($v: total), init(int x = 0;), action(x++;), result(x))", 'actions.say("a", "b");'),
    ("Order() from $orders", 'actions.say("a", "b");'),
    ("$o: Order()\n Line(order == $o.customer.id)", 'actions.say("a", "b");'),
    ("Order(total > 010)", 'actions.say("a", "b");'),
    ("Order(code == \"a\\\"b\")", 'actions.say("a", "b");'),
    ("Order(code == 'a')", 'actions.say("a", "b");'),
    ("Order(code == null)", 'actions.say("a", "b");'),
    ("Order(total > 1e3)", 'actions.say("a", "b");'),
    ("$o: Order()", 'actions.say("a", 1 + $o.getId());'),
    ("$o: Order()", 'actions.say("a", $o.getId() + "b");'),
    ("$o: Order()", 'actions.say("a", $o.id);'),
    ("$o: Order()", 'actions.say("a", $o.setId());'),
    ("$o: Order()", 'actions.say("a", $o.getLine(1));'),
    ("$o: Order()", 'actions.say("a", $o.getCustomer().getName());'),
    ("$o: Order()", "modify($o) { setTotal(2) }"),
    ("$o: Order()", "insert(new Line());"),
    ("$o: Order()", 'System.out.println("x");'),
    ("$o: Order()", '$o.setTotal(3);'),
    ("$o: Order()", 'actions.say("a", "b")'),
    ("Order() over window:time(1m)", 'actions.say("a", "b");'),
    ("accumulate(Order($v: total); $t: sum($v); $t > 1 && $t < 3)", 'actions.say("a", "b");'),
    ("@watch(*) Order()", 'actions.say("a", "b");'),
    ("Order(総額 > 1)", 'actions.say("a", "b");'),
])
def test_other_shapes_are_left_to_the_compiler(when, then):
    assert describe(f'rule "x"\nwhen\n    {when}\nthen\n    {then}\nend') is None


@pytest.mark.parametrize("attribute", ["enabled false", "salience 1 salience 2", "no-loop no-loop",
                                       "ruleflow-group \"f\"", "duration(100)", "timer(int: 1s)", "dialect \"mvel\"",
                                       "agenda-group g", "@Author(me)", "extends base"])
def test_other_attributes_are_left_to_the_compiler(attribute):
    assert describe(f'rule "x" {attribute}\nwhen\n    Order()\nthen\n    actions.say("a", "b");\nend') is None


def test_the_usual_attributes_are_described():
    spec = describe('rule "x"\nagenda-group "g1" activation-group "one"\nauto-focus true no-loop lock-on-active false\n'
                    'date-effective "01-Jan-2020" date-expires "01-JAN-2099" salience -2\n'
                    'when\n    Order()\nthen\n    actions.say("a", "b");\nend')
    assert spec["salience"] == -2
    assert spec["attributes"] == {"agenda-group": "g1", "activation-group": "one", "auto-focus": True, "no-loop": True,
                                  "lock-on-active": False, "date-effective": "01-Jan-2020", "date-expires": "01-JAN-2099"}


def test_bound_fields_in_matches_negations_and_from_accumulate_are_described():
    spec = describe("""rule "x"
    when
        $a: Applicant(region in ("r1", "r2"), age not in (1, 2), email matches ".*@d[.]com", id not matches "x", $id: id)
        $l: Loan(applicant == $id, amount > 5.0)
        not Loan(applicant == $id, purpose == "p")
        exists( Loan(applicant == $id) )
        $n: Number(intValue >= 2) from accumulate(Loan(applicant == $id, $m: amount), count(1))
        Number(doubleValue < 9.5) from accumulate(Loan(applicant == $id, $m: amount), min($m))
    then
        actions.say("a", "b " + $id + $n);
    end""")
    applicant, loan, no, some, count, least = spec["lhs"]
    assert [c["op"] for c in applicant["pattern"]["constraints"]] == ["in", "not in", "matches", "not matches"]
    assert applicant["pattern"]["constraints"][0]["literals"] == [{"s": "r1"}, {"s": "r2"}]
    assert applicant["pattern"]["constraints"][1]["text"] == "age not in ( 1, 2 )"
    assert applicant["pattern"]["binds"] == [{"var": "$id", "field": "id"}]
    assert loan["pattern"]["constraints"][0] == {"field": "applicant", "op": "==", "ref": "$id", "text": "applicant == $id"}
    assert no["not"]["type"] == "Loan" and some["exists"]["constraints"][0]["ref"] == "$id"
    acc = count["fromAccumulate"]
    assert (acc["function"], acc["arg"], acc["result"]["var"], acc["result"]["type"]) == ("count", {"n": "1"}, "$n", "Number")
    assert acc["result"]["constraints"][0]["field"] == "intValue" and acc["source"]["binds"] == [{"var": "$m", "field": "amount"}]
    assert least["fromAccumulate"]["arg"] == {"var": "$m"} and least["fromAccumulate"]["result"]["var"] is None


def test_why_not_names_the_first_thing_the_reader_does_not_take():
    text = 'rule "x"\nwhen\n    Order(total > 1e3)\nthen\nend'
    src = SourceItems("a.drl", "p", text, [Item("rule", "x", 0, len(text), 1)])
    assert plain_rules.why_not(src, src.items[0], []) .startswith("a number with a suffix")
    assert plain_rules.why_not(src, src.items[0], None).startswith("a package header")
    text = 'rule "y"\nwhen\n    Order()\nthen\nend'
    ok = SourceItems("b.drl", "p", text, [Item("rule", "y", 0, len(text), 1)])
    assert plain_rules.why_not(ok, ok.items[0], []) is None
    assert plain_rules.reasons([src, ok]) == {"plain": 1, "a number with a suffix, exponent or radix (1L, 1e3, 0x1)": 1}


def test_a_package_header_with_more_than_imports_and_globals_is_all_compiled():
    plain = SourceItems("a.drl", "p", "package p;\nimport a.B;\nimport c.*\nglobal a.Actions actions;\n", [])
    other = SourceItems("b.drl", "q", 'package q;\ndialect "mvel"\n', [])
    functions = SourceItems("c.drl", "r", "package r;\nimport function a.b.f;\n", [])
    assert plain_rules.package_imports([plain, other, functions]) == {"p": ["a.B", "c.*"], "q": None, "r": None}
