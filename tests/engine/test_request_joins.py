"""One-shot fires of an all-plain rule set read the facts of every pattern after a rule's first
from the request (a request-join network, RequestFacts.java), instead of Drools staging every
fact in the memory of every join, not, exists and accumulate over its type (issue 30: ~13,000
right tuples of a 5-fact request at 10,000 business rules). These tests hold it to the rule
base's own network: the same answer — rules, order, the facts of each firing, actions and facts —
on random business bases and on a set with several joined types, keyed and unkeyed joins and
large requests; and it is used only where that holds."""

from __future__ import annotations

import json
import random
import sys
from pathlib import Path

import pytest

from gateway.engine import compiler, incremental
from gateway.engine.build import CompileOptions
from gateway.engine.results import encode_facts, fired_of

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench" / "peers"))
from business_rules import BusinessRules


@pytest.fixture()
def options(tmp_path) -> CompileOptions:
    """``always``: these sets are small, so ``auto`` would keep the rule base's network (see
    test_auto_builds_it_where_facts_fan_out_widely)."""
    incremental.reset()
    yield CompileOptions(cache_dir=str(tmp_path / "units"), request_joins="always")
    incremental.reset()


def decoded(answer: str) -> dict:
    """A runner's answer with each firing's facts in it (a request-join fire sends each fact once,
    in ``factTable``: results.fired_of puts them back)."""
    data = json.loads(answer)
    if data.get("ok"):
        fired_of(data)
        data.pop("factTable", None)
    return data


def answers_alike(compiled, requests: list[list[dict]]) -> None:
    """Each request fired by the set's runner (request joins, sessions reused) answers exactly as
    a runner of the rule base's own network (a fresh one each time) does."""
    from gateway.base import jvm

    runner_class = jvm.helper_class("Runner")
    for k, facts in enumerate(requests):
        data = encode_facts(facts, 10_000)
        joined = decoded(str(compiled.runner.fire(data, 100_000, True, True)))
        network = decoded(str(runner_class(compiled.kbase).fire(data, 100_000, True, True)))
        assert joined["ok"], (k, joined)
        assert joined == network, k


def without_auto_focus(rules: BusinessRules) -> dict[str, str]:
    """The base's files with its agenda groups kept and their auto-focus dropped (those rules then
    never fire: no rule gives their group the focus): a set the request-join network fires exactly."""
    return {name: text.replace("auto-focus true\n", "") for name, text in rules.drl_files().items()}


@pytest.mark.parametrize("seed,attributes", [(1, 0.3), (2, 0.0), (3, 0.6)])
def test_a_random_business_base_answers_as_its_own_network(options, seed, attributes):
    """300 rules of every shape (joins, count/sum/min/max accumulates, not, exists, in, matches,
    then-part calls), with salience, agenda groups, no-loop, lock-on-active and rule dates, or
    without attributes; 60 requests of up to 5 applicants and 8 loans: the same answers, in order."""
    rules = BusinessRules(seed, 300, regions=6, segments=3, purposes=3, domains=3, attribute_share=attributes)
    compiled = compiler.compile_files(without_auto_focus(rules), f"joins{seed}", options)
    assert compiled.stats.rules_built == 300 and compiled.runner.readsJoinsFromRequest()
    assert compiled.stats.request_joins_s > 0
    requests = [rules.facts(k, applicants=1 + k % 5, loans=k % 9) for k in range(60)]
    answers_alike(compiled, requests)
    if attributes == 0.0:  # and as the model of the rules' meaning says
        for facts in requests[:10]:
            fired = decoded(str(compiled.runner.fire(encode_facts(facts, 10_000), 10_000, False, False)))["fired"]
            counts: dict[str, int] = {}
            for one in fired:
                counts[one["rule"]] = counts.get(one["rule"], 0) + 1
            assert counts == {r: len(t) for r, t in rules.expected(facts).items()}


def fanning_out(rules: int, auto_focus: bool = False) -> dict[str, str]:
    """A set whose loans each enter ``rules`` memories untested (a ``not`` per rule, straight under
    the loan type), one rule with auto-focus if asked."""
    text = "package org.joins;\n\n" + "\n".join(
        f'rule "r{k}"\n{"auto-focus true" if auto_focus and k == 0 else ""}\nwhen\n'
        f'    $p : Person( age == {k}, $id : id )\n    not Loan( applicant == $id )\nthen\n'
        f'    actions.say("bot", "r{k}");\nend\n' for k in range(rules))
    return {"types.drl": TYPES, "rules.drl": text}


def test_auto_builds_it_where_facts_fan_out_widely(tmp_path):
    """``auto`` (the default) builds a request-join network where it pays: facts of a type enter at
    least Runner.REQUEST_JOINS_FAN_OUT memories untested, with auto-focus rules or without; below
    that, the rule base serves."""
    from gateway.base import jvm

    fan_out = int(jvm.helper_class("Runner").REQUEST_JOINS_FAN_OUT)
    wide = compiler.compile_files(fanning_out(fan_out), "wide", CompileOptions(cache_dir=str(tmp_path / "w")))
    assert int(jvm.helper_class("DroolsInternals").untestedRightInputs(wide.kbase)) == fan_out
    assert wide.runner.readsJoinsFromRequest()
    answers_alike(wide, [[{"type": "Person", "id": "p", "region": "n", "age": 3}],
                         [{"type": "Person", "id": "p", "region": "n", "age": 3},
                          {"type": "Loan", "id": "l", "applicant": "p", "amount": 1.0}]])
    narrow = compiler.compile_files(fanning_out(fan_out - 1), "narrow", CompileOptions(cache_dir=str(tmp_path / "n")))
    assert not narrow.runner.readsJoinsFromRequest()
    focus = compiler.compile_files(fanning_out(fan_out, auto_focus=True), "focus", CompileOptions(cache_dir=str(tmp_path / "f")))
    assert focus.runner.readsJoinsFromRequest()  # auto-focus rules too: they answer alike (DroolsLinkOrder)


def test_auto_focus_sets_built_in_several_units_answer_as_the_rule_base(options, monkeypatch, tmp_path):
    """A business set with auto-focus rules in four agenda groups, built in units of 100 rules (as
    10,000 rules are built in units of 2,000). The rule base shares the nodes of rules that open
    alike across units, as one build of the whole set does, and the request-join network shares
    them as the rule base: every request answers as the rule base's own network, each rule's
    matches in order (the agenda groups take the focus in the rule base's order: DroolsLinkOrder).
    Before the plain builder's field readers compared by value, units never shared a join, and a
    rule that opened as an auto-focus rule in another unit fired its matches in another order."""
    from gateway.base import jvm

    # no tier shared with other hosts (an app made by another test of this worker may have left
    # one): the second build must make its units, not assemble the first one's plan from there
    monkeypatch.setattr(incremental, "_shared", None)
    incremental.reset()
    rules = BusinessRules(6, 300, regions=6, segments=3, purposes=3, domains=3, attribute_share=0.6)
    assert any(r.attribute == "agenda-group" for r in rules.rules())
    requests = [rules.facts(k, applicants=1 + k % 5, loans=k % 9) for k in range(60)]
    one_unit = compiler.compile_files(rules.drl_files(), "one unit", options)
    monkeypatch.setattr(incremental, "MAX_PLAIN_BATCH", 100)
    units = compiler.compile_files(rules.drl_files(), "units",
                                   CompileOptions(cache_dir=str(tmp_path / "small units"), request_joins="always"))
    assert units.stats.rules_built == 300 and units.runner.readsJoinsFromRequest()
    answers_alike(units, requests)
    runner_class = jvm.helper_class("Runner")
    for k, facts in enumerate(requests):  # the rule base of three units answers as that of one
        data = encode_facts(facts, 10_000)
        assert decoded(str(runner_class(units.kbase).fire(data, 100_000, True, True))) == decoded(
            str(runner_class(one_unit.kbase).fire(data, 100_000, True, True))), k


TYPES = """package org.joins;
import org.printeps.gateway.Actions;
global Actions actions;

declare Person
    id : String
    region : String
    age : int
end

declare Loan
    id : String
    applicant : String
    amount : double
end

declare Payment
    id : String
    applicant : String
    amount : double
end

declare Tag
    owner : int
    label : String
end
"""

RULES = """package org.joins;

rule "loan of a northern person"
when
    $p : Person( region == "n", $id : id )
    $l : Loan( applicant == $id )
then
    actions.say("bot", "loan " + $l.getId());
end

rule "payment of a northern person"
when
    $p : Person( region == "n", $id : id )
    $x : Payment( applicant == $id )
then
    actions.say("bot", "payment " + $x.getId());
end

rule "loan by a field of the person"
salience 5
when
    $p : Person( region == "s" )
    $l : Loan( applicant == $p.id )
then
    actions.say("bot", "field " + $l.getId());
end

rule "tag of the age"
when
    $p : Person( $age : age )
    $t : Tag( owner == $age )
then
    actions.say("bot", "tag " + $t.getLabel());
end

rule "payment as big as a loan"
when
    $l : Loan( $amount : amount )
    $x : Payment( amount == $amount )
then
    actions.say("bot", "same " + $x.getId());
end

rule "two loans"
when
    $p : Person( $id : id )
    Number( intValue >= 2 ) from accumulate( Loan( applicant == $id ), count( 1 ) )
then
    actions.say("bot", "two " + $p.getId());
end

rule "paid over a hundred"
when
    $p : Person( $id : id )
    Number( doubleValue > 100.0 ) from accumulate( Payment( applicant == $id, $m : amount ), sum( $m ) )
then
    actions.say("bot", "paid " + $p.getId());
end

rule "no loan"
when
    $p : Person( $id : id )
    not Loan( applicant == $id )
then
    actions.say("bot", "none " + $p.getId());
end

rule "some big loan"
when
    $p : Person( )
    exists Loan( amount > 1000.0 )
then
    actions.say("bot", "big " + $p.getId());
end

rule "loan then its payment"
when
    $p : Person( $id : id )
    $l : Loan( applicant == $id )
    $x : Payment( applicant == $id, amount < 500.0 )
then
    actions.say("bot", "chain " + $l.getId() + " " + $x.getId());
end
"""


def typed_requests(seed: int, count: int, scale: int = 1) -> list[list[dict]]:
    rng = random.Random(seed)
    out = []
    for _ in range(count):
        persons = [{"type": "Person", "id": f"p{k}", "region": rng.choice("ns"), "age": rng.randrange(20, 24)}
                   for k in range(rng.randrange(0, 5 * scale))]
        ids = [p["id"] for p in persons] + ["nobody"]
        amounts = [50.0, 200.0, 800.0, 1500.0]
        facts = persons + [{"type": "Loan", "id": f"l{k}", "applicant": rng.choice(ids), "amount": rng.choice(amounts)}
                           for k in range(rng.randrange(0, 7 * scale))]
        facts += [{"type": "Payment", "id": f"x{k}", "applicant": rng.choice(ids), "amount": rng.choice(amounts)}
                  for k in range(rng.randrange(0, 5 * scale))]
        facts += [{"type": "Tag", "owner": rng.randrange(20, 24), "label": f"t{k}"} for k in range(rng.randrange(0, 3 * scale))]
        rng.shuffle(facts)  # the request's order is the order joined facts arrive in
        out.append(facts)
    return out


def test_several_joined_types_keyed_and_unkeyed_joins_answer_as_the_network(options):
    """Rules that share their first pattern and join different types (a shared node read by type
    would mix them up), a join on a field of a bound fact, on an int, on a double (not keyed), a
    chain of two joins, accumulates, not and an uncorrelated exists; then requests of up to a
    few hundred facts."""
    files = {"types.drl": TYPES, "rules.drl": RULES}
    compiled = compiler.compile_files(files, "typed", options)
    assert compiled.stats.rules_built == 10 and compiled.runner.readsJoinsFromRequest()
    answers_alike(compiled, typed_requests(1, 80))
    answers_alike(compiled, typed_requests(2, 6, scale=10))


IN_RULES = """package org.joins;

rule "north or east"
when
    $p : Person( region in ( "n", "e" ) )
then
    actions.say("bot", "ne " + $p.getId());
end

rule "north or east, locked"
lock-on-active true
when
    $p : Person( region in ( "n", "e" ) )
then
    actions.say("bot", "ne locked " + $p.getId());
end

rule "north or east and older"
salience 3
when
    $p : Person( region in ( "n", "e" ), age > 20 )
then
    actions.say("bot", "ne older " + $p.getId());
end

rule "even age"
when
    $p : Person( age in ( 20, 22 ) )
then
    actions.say("bot", "even " + $p.getId());
end

rule "two lists"
when
    $p : Person( region in ( "s", "w", "n" ), age in ( 21, 23 ) )
then
    actions.say("bot", "two lists " + $p.getId());
end

rule "not north"
when
    $p : Person( region not in ( "n" ) )
then
    actions.say("bot", "not n " + $p.getId());
end

rule "loan of a southern or western person"
when
    $p : Person( region in ( "s", "w" ), $id : id )
    $l : Loan( applicant == $id )
then
    actions.say("bot", "sw loan " + $l.getId());
end

rule "big loans unpaid"
when
    $l : Loan( applicant in ( "p0", "p1", "p2" ), $id : applicant )
    not Payment( applicant == $id )
then
    actions.say("bot", "unpaid " + $l.getId());
end

rule "small loan then a payment"
lock-on-active true
when
    $l : Loan( id in ( "l0", "l1", "l2", "l3" ), $id : applicant )
    $x : Payment( applicant == $id )
then
    actions.say("bot", "paid small " + $l.getId() + " " + $x.getId());
end
"""


def test_root_in_tests_dispatched_by_value_answer_as_the_network(options):
    """Rules whose first pattern starts with an ``in`` get it dispatched by value (RequestDispatch):
    one pattern alone, with lock-on-active (Drools builds it otherwise), with more tests, on an
    int, two lists, followed by a join, by a ``not`` or by a join in a locked rule; a ``not in``
    stays a test, and so does a pattern that opens two rules (test_rules_that_open_alike_share_as_in_the_rule_base). Requests of up to a few hundred facts answer as the rule
    base's own network, in order."""
    files = {"types.drl": TYPES, "rules.drl": IN_RULES}
    compiled = compiler.compile_files(files, "dispatched", options)
    assert compiled.runner.readsJoinsFromRequest()
    # ne older, even, two lists and the three joins; "north or east" opens two rules: not dispatched
    assert compiled.runner.routedPatterns() == 6
    rng = random.Random(7)
    requests = typed_requests(3, 80) + typed_requests(4, 6, scale=10)
    for facts in requests:
        for f in facts:
            if f["type"] == "Person":
                f["region"] = rng.choice("nsew")
    answers_alike(compiled, requests)
    fired = {f["rule"] for facts in requests
             for f in decoded(str(compiled.runner.fire(encode_facts(facts, 10_000), 100_000, True, True)))["fired"]}
    assert fired >= {"north or east", "north or east, locked", "north or east and older", "even age", "two lists",
                     "loan of a southern or western person", "big loans unpaid", "small loan then a payment"}


TWINS = """package org.joins;

rule "twin a"
when
    $p : Person( region in ( "n", "e" ), age > 30 )
then
    actions.say("bot", "a " + $p.getId());
end

rule "twin b"
when
    $p : Person( region in ( "n", "e" ), age > 30 )
then
    actions.say("bot", "b " + $p.getId());
end

rule "loan twin a"
when
    $p : Person( region in ( "s", "w" ), $id : id )
    $l : Loan( applicant == $id, amount > 100.0 )
then
    actions.say("bot", "a " + $l.getId());
end

rule "loan twin b"
salience 1
when
    $p : Person( region in ( "s", "w" ), $id : id )
    $l : Loan( applicant == $id, amount > 100.0 )
then
    actions.say("bot", "b " + $l.getId());
end

rule "focused"
auto-focus true
agenda-group "f"
when
    $p : Person( region == "n", $id : id )
    $l : Loan( applicant == $id, amount > 50.0 )
then
    actions.say("bot", "f " + $l.getId());
end

rule "opens as focused"
when
    $p : Person( region == "n", $id : id )
    $l : Loan( applicant == $id, amount > 50.0 )
then
    actions.say("bot", "o " + $l.getId());
end

rule "exists as focused"
when
    $p : Person( region == "e", $id : id )
    exists Loan( applicant == $id, amount > 20.0 )
then
    actions.say("bot", "eo " + $p.getId());
end

rule "focused exists"
auto-focus true
agenda-group "g"
when
    $p : Person( region == "e", $id : id )
    exists Loan( applicant == $id, amount > 20.0 )
then
    actions.say("bot", "fe " + $p.getId());
end
"""


def test_rules_that_open_alike_share_as_in_the_rule_base(options):
    """Drools shares the nodes of rules that open alike, and the order a shared node hands its
    matches on depends on the rules it is shared with (two rules of one pattern fire their matches
    in opposite orders). So a first pattern that opens two rules is not dispatched by value, and a
    rule that opens as an auto-focus rule does (a join, an ``exists``) gets its guards
    (shared_patterns.py): every request answers as the rule base's own network, each rule's
    matches in order."""
    compiled = compiler.compile_files({"types.drl": TYPES, "rules.drl": TWINS}, "twins", options)
    assert compiled.runner.readsJoinsFromRequest() and compiled.runner.routedPatterns() == 0
    rng = random.Random(11)
    requests = typed_requests(5, 60, scale=3)  # several persons of a region: a rule matches twice or more
    for facts in requests:
        for f in facts:
            if f["type"] == "Person":
                f["region"], f["age"] = rng.choice("nsew"), rng.randrange(20, 50)
    answers_alike(compiled, requests)
    fired = {f["rule"] for facts in requests
             for f in decoded(str(compiled.runner.fire(encode_facts(facts, 10_000), 100_000, True, True)))["fired"]}
    assert fired == {"twin a", "twin b", "loan twin a", "loan twin b", "focused", "opens as focused",
                     "focused exists", "exists as focused"}


def auto_focus_rules(pattern: str, groups: dict[str, str]) -> str:
    """One auto-focus rule of one pattern per agenda group: ``pattern`` with the group's test in it."""
    return "".join(f"""
rule "focus {name}"
auto-focus true
agenda-group "{name}"
when
    $f : {pattern.format(test)}
then
    actions.say("bot", "{name} " + $f.getId());
end
""" for name, test in groups.items())


def shared_first_test(plain_rules: int) -> str:
    """Two auto-focus rules of one pattern and ``plain_rules`` others, all opening with one ``in``
    test: Drools' node for that test has a child per rule, range-indexed on age from nine."""
    focused = auto_focus_rules('Person( region in ( "n", "e" ), age > {} )', {"older": "40", "old": "30"})
    plain = "".join(f"""
rule "plain {k}"
when
    $p : Person( region in ( "n", "e" ), age > {20 + 3 * k} )
then
    actions.say("bot", "plain {k} " + $p.getId());
end
""" for k in range(plain_rules))
    return "package org.joins;\n" + focused + plain


def test_rules_sharing_an_auto_focus_rules_first_test_are_not_dispatched(options):
    """An auto-focus rule of one pattern gets its match, and pushes its agenda group, when a fact
    reaches its node, in the order its parent node hands facts to its children, and that order
    depends on how many children test one field (range-indexed from nine). Rules opening with the
    same first test as an auto-focus rule keep it (shared_patterns.py), so that node has the same
    children as in the rule base: the groups take the focus in the rule base's order (with those
    rules dispatched, "old" fired before "older")."""
    compiled = compiler.compile_files({"types.drl": TYPES, "rules.drl": shared_first_test(8)}, "first test", options)
    assert compiled.runner.readsJoinsFromRequest() and compiled.runner.routedPatterns() == 0
    requests = [[{"type": "Person", "id": f"p{k}", "region": region, "age": age} for k, (region, age) in enumerate(people)]
                for people in ([("n", 45)], [("e", 35), ("n", 50)], [("s", 60), ("e", 41)], [("n", 25)])]
    answers_alike(compiled, requests)
    first = decoded(str(compiled.runner.fire(encode_facts(requests[0], 100), 1000, False, False)))["fired"]
    assert [f["rule"] for f in first[:2]] == ["focus older", "focus old"]


def test_a_set_whose_auto_focus_rules_of_one_pattern_move_keeps_the_rule_base(options):
    """Two auto-focus rules of one loan pattern and eight joins whose loan patterns test the same
    field: in the rule base a loan's node hands facts to the ten children range-indexed (by
    amount), in the request-join network (the joins read loans from the request) to the two in
    the order they were added, so a loan would reach "medium" first and its group take the focus
    last. DroolsLinkOrder.sameFocusOrder sees it and the set keeps the rule base's network."""
    focused = auto_focus_rules("Loan( amount > {} )", {"big": "100.0", "medium": "50.0"})
    joins = "".join(f"""
rule "join {k}"
when
    $p : Person( $id : id )
    $l : Loan( amount > {10.0 + 20 * k}, applicant == $id )
then
    actions.say("bot", "join {k} " + $l.getId());
end
""" for k in range(8))
    compiled = compiler.compile_files({"types.drl": TYPES, "rules.drl": "package org.joins;\n" + focused + joins},
                                      "focus moves", options)
    assert compiled.stats.request_joins_s > 0 and not compiled.runner.readsJoinsFromRequest()
    facts = [{"type": "Person", "id": "p0", "region": "n", "age": 45},
             {"type": "Loan", "id": "l0", "applicant": "p0", "amount": 500.0}]
    fired = decoded(str(compiled.runner.fire(encode_facts(facts, 100), 1000, False, False)))["fired"]
    assert [f["rule"] for f in fired[:2]] == ["focus big", "focus medium"]
    fewer = compiler.compile_files({"types.drl": TYPES, "rules.drl": "package org.joins;\n" + focused}, "focus stays", options)
    assert fewer.runner.readsJoinsFromRequest()  # nothing moves: the request-join network serves


def test_a_request_reads_only_its_own_facts(options):
    """Two runners' worth of requests in turn on one session pool: nothing of a request is joined
    in the next one (the request's facts are closed after its fire), and an empty request fires
    nothing."""
    compiled = compiler.compile_files({"types.drl": TYPES, "rules.drl": RULES}, "own", options)
    person = {"type": "Person", "id": "p0", "region": "n", "age": 20}
    first = decoded(str(compiled.runner.fire(encode_facts([person, {"type": "Loan", "id": "l0", "applicant": "p0",
                                                                          "amount": 50.0}], 100), 100, False, False)))
    assert "loan l0" in [a["params"]["text"] for a in first["actions"]]
    second = decoded(str(compiled.runner.fire(encode_facts([person], 100), 100, False, False)))
    texts = [a["params"]["text"] for a in second["actions"]]
    assert "none p0" in texts and not any(t.startswith("loan") for t in texts)
    assert decoded(str(compiled.runner.fire("[]", 100, False, False)))["fireCount"] == 0


def test_a_request_fire_sends_each_matched_fact_once(options):
    """A request-join fire's answer carries each matched fact once (``factTable``) and each firing
    its facts' numbers; decoded, every firing has its own copy of its facts, as the rule base's
    runner writes them at every firing."""
    from gateway.base import jvm
    from gateway.engine.results import decode_result

    compiled = compiler.compile_files({"types.drl": TYPES, "rules.drl": RULES}, "table", options)
    facts = [{"type": "Person", "id": "p0", "region": "n", "age": 20},
             {"type": "Loan", "id": "l0", "applicant": "p0", "amount": 50.0},
             {"type": "Loan", "id": "l1", "applicant": "p0", "amount": 1500.0},
             {"type": "Payment", "id": "x0", "applicant": "p0", "amount": 50.0}]
    data = encode_facts(facts, 100)
    raw = json.loads(str(compiled.runner.fire(data, 100, False, True)))
    numbers = [k for firing in raw["fired"] for k in firing["facts"]]
    assert all(isinstance(k, int) for k in numbers) and len(numbers) > len(raw["factTable"]) == len(set(numbers))
    result = decode_result(str(compiled.runner.fire(data, 100, False, True)), "table", 1, 0.0)
    network = json.loads(str(jvm.helper_class("Runner")(compiled.kbase).fire(data, 100, False, True)))
    assert "factTable" not in network and result.fired == network["fired"]
    persons = [f for firing in result.fired for f in firing["facts"] if isinstance(f, dict) and f.get("type") == "Person"]
    assert len(persons) > 1 and len({id(p) for p in persons}) == len(persons)


def test_only_all_plain_sets_without_events_use_request_joins(options, tmp_path):
    """A then-part that inserts or modifies facts (compiled by Drools) changes facts while a
    request fires, and an event's expiry belongs to the session: both keep the network itself, as
    does ``compile_request_joins: never``. Sessions, KIE batches and explain always use it."""
    changing = RULES + """
rule "grow"
when
    $p : Person( age < 21 )
then
    modify( $p ) { setAge( 21 ) };
end
"""
    compiled = compiler.compile_files({"types.drl": TYPES, "rules.drl": changing}, "changing", options)
    assert compiled.stats.rules_compiled >= 1 and not compiled.runner.readsJoinsFromRequest()
    events = TYPES.replace("declare Tag\n", "declare Tag\n    @role( event )\n")
    compiled = compiler.compile_files({"types.drl": events, "rules.drl": RULES}, "events", options)
    assert not compiled.runner.readsJoinsFromRequest()
    five = RULES + """
rule "five variables"
when
    $p : Person( $i : id, $r : region )
    $l : Loan( $li : id, $la : applicant )
    $t : Tag( $tl : label )
    not Payment( id == $i, applicant == $r, id != $li, applicant != $la, id != $tl )
then
    actions.say("bot", "five");
end
"""
    # a not reading more than four variables builds plain, but not from the request: the set
    # keeps its own network (logged with the reason) and fires as before
    compiled = compiler.compile_files({"types.drl": TYPES, "rules.drl": five}, "five", options)
    assert compiled.stats.rules_compiled == 0 and not compiled.runner.readsJoinsFromRequest()
    facts = [{"type": "Person", "id": "p", "region": "n", "age": 20}, {"type": "Loan", "id": "l", "applicant": "a", "amount": 1.0},
             {"type": "Tag", "owner": 20, "label": "t"}, {"type": "Payment", "id": "p", "applicant": "s", "amount": 1.0}]
    answer = decoded(str(compiled.runner.fire(encode_facts(facts, 100), 100, False, False)))
    assert "five" in [a["params"]["text"] for a in answer["actions"]]
    off = CompileOptions(cache_dir=str(tmp_path / "off"), request_joins="never")
    compiled = compiler.compile_files({"types.drl": TYPES, "rules.drl": RULES + "\n"}, "off", off)
    assert compiled.stats.request_joins_s == 0 and not compiled.runner.readsJoinsFromRequest()
