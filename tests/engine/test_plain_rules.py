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
    ("not Order()", 'actions.say("a", "b");'),
    ("exists Order()", 'actions.say("a", "b");'),
    ("Order() from $orders", 'actions.say("a", "b");'),
    ("eval(true)", 'actions.say("a", "b");'),
    ("Order(total > 1 && total < 5)", 'actions.say("a", "b");'),
    ("Order(total > 1 || total < 5)", 'actions.say("a", "b");'),
    ("Order(total in (1, 2))", 'actions.say("a", "b");'),
    ("Order(code matches \"a.*\")", 'actions.say("a", "b");'),
    ("Order(getTotal() > 1)", 'actions.say("a", "b");'),
    ("$o: Order()\n Line(order == $o)", 'actions.say("a", "b");'),
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
    ("$t: Number() from accumulate(Order($v: total), sum($v))", 'actions.say("a", "b");'),
    ("accumulate(Order($v: total); $t: sum($v); $t > 1 && $t < 3)", 'actions.say("a", "b");'),
    ("@watch(*) Order()", 'actions.say("a", "b");'),
    ("Order(総額 > 1)", 'actions.say("a", "b");'),
])
def test_other_shapes_are_left_to_the_compiler(when, then):
    assert describe(f'rule "x"\nwhen\n    {when}\nthen\n    {then}\nend') is None


@pytest.mark.parametrize("attribute", ["no-loop", "no-loop true", "agenda-group \"g\"", "enabled false",
                                       "salience 1 salience 2",
                                       "@Author(me)", "extends base"])
def test_attributes_other_than_salience_are_left_to_the_compiler(attribute):
    assert describe(f'rule "x" {attribute}\nwhen\n    Order()\nthen\n    actions.say("a", "b");\nend') is None


def test_a_package_header_with_more_than_imports_and_globals_is_all_compiled():
    plain = SourceItems("a.drl", "p", "package p;\nimport a.B;\nimport c.*\nglobal a.Actions actions;\n", [])
    other = SourceItems("b.drl", "q", 'package q;\ndialect "mvel"\n', [])
    functions = SourceItems("c.drl", "r", "package r;\nimport function a.b.f;\n", [])
    assert plain_rules.package_imports([plain, other, functions]) == {"p": ["a.B", "c.*"], "q": None, "r": None}
