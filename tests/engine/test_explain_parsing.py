"""Explain's reading of a rule's conditions (no JVM): top-level conditions, their kinds and
pattern parts, and the words a reason is made of. Real rule texts, no mocks."""

from __future__ import annotations

import pytest

from datetime import date

from gateway.engine.explain_plan import _sentences, has_candidates, rule_attributes, split_conditions
from gateway.engine.explain_reasons import _wants, held_back
from gateway.engine.replay import not_replayable, same_outcome

LHS = '''
    $e: Entrance()
    exists Customer(entrance == $e.id) not Customer(entrance == $e.id, category != "adult")
    $i : Item( price > 3, name == "a, b" ) from $o.items
    $x : Foo( a == 1 ||
        b == 2 ) over window:time(5m)
    Number( intValue >= 5 ) from accumulate( Visit( guest == $g.id ), count(1) )
    eval( true )
    // a comment ( with a bracket
    not ( Crowded( hall == "main" ) )
'''


def test_conditions_are_split_at_the_top_level_with_their_lines():
    conds = split_conditions(LHS, 10)
    assert [(c.kind, c.line) for c in conds] == [
        ("pattern", 11), ("exists", 12), ("not", 12), ("from", 13), ("pattern", 14), ("accumulate", 16),
        ("eval", 17), ("not", 19)]
    assert conds[1].drl == "exists Customer(entrance == $e.id)"
    assert conds[2].type == "Customer" and conds[2].constraints == ["entrance == $e.id", 'category != "adult"']
    assert conds[3].constraints == ["price > 3", 'name == "a, b"'] and conds[3].suffix == "from $o.items"
    assert conds[4].constraints == ["a == 1 ||\n        b == 2"] and conds[4].suffix.startswith("over window")
    assert conds[5].type == "Number" and conds[5].constraints == ["intValue >= 5"]
    assert conds[7].type == "Crowded" and conds[7].constraints == ['hall == "main"']


def test_a_candidate_query_binds_the_fact_and_keeps_a_prefix_of_the_constraints():
    cond = split_conditions('    $i : Item( price > 3, name == "x" ) from $o.items\n', 1)[0]
    assert cond.candidate(0) == "$__f : Item(  ) from $o.items"
    assert cond.candidate(1) == "$__f : Item( price > 3 ) from $o.items"


def test_not_and_exists_over_several_patterns_are_said_as_a_whole():
    conds = split_conditions("    not ( Visit( guest == $g.id ) or Visit( amount > 10 ) )\n"
                             "    exists ( Guest( age > 100 ) and Visit( amount > 1000 ) )\n"
                             "    not Visit( amount > 5 ) from $visits\n", 1)
    assert [c.kind for c in conds] == ["other", "other", "not"]


def test_an_accumulate_element_is_asked_with_a_prefix_of_its_constraints():
    cond = split_conditions("    accumulate( Order( customer == $c.id, $a : amount ); $t : sum( $a ), $n : count( 1 );"
                            " $t > 100 && $n >= 2 )\n", 1)[0]
    assert cond.kind == "accumulate" and cond.type is None and has_candidates(cond)
    assert cond.source == "Order( customer == $c.id, $a : amount )" and cond.results() == ["$t", "$n"]
    assert cond.constraints == ["$t > 100", "$n >= 2"]
    assert cond.candidate(0) == "accumulate( Order( customer == $c.id, $a : amount ); $t : sum( $a ), $n : count( 1 ) )"
    assert cond.candidate(1).endswith("; $t > 100 )")
    inline = split_conditions("    accumulate( Order( $a : amount ), init( double t = 0; ), action( t += $a; ),"
                              " result( t ) )\n", 1)[0]
    assert inline.kind == "accumulate" and not has_candidates(inline)  # explained as a whole, asking nothing


@pytest.mark.parametrize("constraint, wanted", [('language == "en"', '"en"'), ("age >= 12", "age >= 12"),
                                                ("$a : age == 3", "3")])
def test_what_the_rule_wants_is_said_plainly(constraint, wanted):
    assert _wants(constraint) == wanted


def test_dsl_sentences_keep_their_dash_lines():
    dslr = 'rule "R"\nwhen\n    There is a guest\n    - older than 11\n    // note\n    The hall is free\nthen\n    x\nend\n'
    assert _sentences(dslr, "R") == [(3, ["There is a guest", "- older than 11"]), (6, ["The hall is free"])]


def test_cut_and_session_decisions_are_not_replayable_and_outcomes_compare_as_multisets():
    assert not_replayable({"facts": [1, 2], "facts_count": 5}).startswith("its facts were cut")
    assert "stateful session 's1'" in not_replayable({"facts": [], "context": {"session": "s1"}})
    assert not_replayable({"facts": [1], "facts_count": 1, "context": {"session": None}}) is None
    a, b = {"module": "say", "params": {"text": "hi", "to": 1}}, {"module": "move", "params": {}}
    assert same_outcome(["A", "B"], [a, b], ["B", "A"], [b, {"params": {"to": 1, "text": "hi"}, "module": "say"}])
    assert not same_outcome(["A"], [a], ["A", "A"], [a, a])
    assert not same_outcome(["A"], [a], ["A"], [b])


def test_a_rule_whose_conditions_hold_is_told_what_held_it_back():
    header = """rule "when agenda-group" // no-loop in a comment
    agenda-group "late"  date-effective "1-Jan-2099"
    no-loop
    activation-group 'x'
    enabled false
when"""
    assert rule_attributes(header) == {"agenda-group": "late", "date-effective": "1-Jan-2099", "no-loop": "true",
                                       "activation-group": "x", "enabled": "false"}
    today = date(2026, 11, 28)
    assert held_back({"enabled": "false"}, frozenset(), today) == "it is disabled (enabled false)"
    assert held_back({"activation-group": "g"}, frozenset({"g"}), today) == 'a rule of its activation group "g" fired first'
    assert held_back({"agenda-group": "late", "lock-on-active": "true"}, frozenset({"h"}), today) == (
        'its agenda group "late" did not have the focus while they held or lock-on-active stopped it')
    assert held_back({"agenda-group": "late", "auto-focus": "true"}, frozenset(), today).startswith("the fire limit")
