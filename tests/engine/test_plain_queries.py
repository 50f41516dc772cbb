"""Queries without parameters of the plain shapes are built at run time, as plain rules are, in
units of their own instead of the declarations unit (``plain_rules.queries_apart``): they answer
exactly as the compiled ones, a query with parameters or one a rule calls stays compiled, and
explain's diagnostic queries (hundreds per version) compile nothing. A real JVM and Drools."""

from __future__ import annotations

import pytest

from gateway.engine import compiler, incremental
from gateway.engine.build import CompileOptions
from gateway.engine.explain import build as build_explainer

from engine_samples import engine_with

DRL = """package org.printeps.q;
import org.printeps.gateway.Actions;
global Actions actions;

declare Guest
    id: String
    age: int
    tier: String
end

declare Visit
    guest: String
    amount: double
end

query "adults"
    $g : Guest( age >= 18 )
end

query vipVisits
    $g : Guest( tier in ( "vip", "gold" ) )
    $v : Visit( guest == $g.id, amount > 10.0 )
end

query "big spenders"
    $g : Guest( )
    accumulate( Visit( guest == $g.id, $a : amount ); $t : sum( $a ); $t > 100.0 )
end

query "no visit yet"
    $g : Guest( tier != "staff" )
    not Visit( guest == $g.id )
end

query "by tier" (String $tier)
    $g : Guest( tier == $tier )
end

query calledByRule
    $g : Guest( age < 18 )
end

rule "welcome"
when
    $g : Guest( age >= 18 )
then
    actions.say("bot", "Hello " + $g.getId());
end

rule "a child"
when
    ?calledByRule()
then
    actions.say("bot", "a child is here");
end
"""

FACTS = [
    {"type": "Guest", "id": "ann", "age": 40, "tier": "vip"},
    {"type": "Guest", "id": "bob", "age": 12, "tier": "basic"},
    {"type": "Guest", "id": "cid", "age": 30, "tier": "gold"},
    {"type": "Guest", "id": "dee", "age": 50, "tier": "staff"},
    {"type": "Visit", "guest": "ann", "amount": 80.0},
    {"type": "Visit", "guest": "ann", "amount": 45.5},
    {"type": "Visit", "guest": "cid", "amount": 5.0},
]

QUERIES = [("adults", []), ("vipVisits", []), ("big spenders", []), ("no visit yet", []), ("by tier", ["vip"]),
           ("calledByRule", [])]


@pytest.fixture()
def options(tmp_path) -> CompileOptions:
    incremental.reset()
    yield CompileOptions(cache_dir=str(tmp_path / "units"))
    incremental.reset()


def test_parameterless_plain_queries_build_plain_and_the_others_compile(options):
    compiled = compiler.compile_files({"q.drl": DRL}, "q", options)
    # "welcome" and the four plain queries no one names; "by tier" (parameters) and the query
    # "a child" calls stay in the compiled declarations unit, and that rule (a query call) is compiled
    assert (compiled.stats.rules, compiled.stats.rules_built, compiled.stats.rules_compiled) == (2, 5, 1), compiled.stats
    # a set's rules are its rules: Drools lists queries among a package's rules, the count does not
    assert (compiled.rule_count, compiled.rule_names) == (2, ["a child", "welcome"])
    again = compiler.compile_files({"q.drl": DRL}, "q", options)  # assembled from its saved plan
    assert (again.stats.mode, again.stats.rules, again.rule_count) == ("plan", 2, 2), again.stats


def _answers(tmp_path, plain: bool) -> tuple[list, list]:
    engine = engine_with(tmp_path / ("plain" if plain else "compiled"), "q", {"q.drl": DRL}, compile_plain_rules=plain)
    session = engine.open_session("q")
    try:
        session.insert(FACTS)
        session.fire()
        answers = []
        for name, arguments in QUERIES:
            got = session.query(name, arguments)
            answers.append((name, sorted(got["identifiers"]), sorted(
                (sorted((k, str(v)) for k, v in row.items()) for row in got["rows"]))))
        fired = engine.fire("q", FACTS).fired
        return answers, [f["rule"] for f in fired]
    finally:
        session.close()


def test_plain_queries_answer_as_compiled_ones(tmp_path):
    plain, plain_fired = _answers(tmp_path, True)
    compiled, compiled_fired = _answers(tmp_path, False)
    assert plain == compiled
    assert plain_fired == compiled_fired and "a child" in plain_fired
    rows = {name: rows for name, _, rows in plain}
    assert len(rows["adults"]) == 3 and len(rows["vipVisits"]) == 2 and len(rows["big spenders"]) == 1
    assert len(rows["no visit yet"]) == 1 and len(rows["by tier"]) == 1  # bob: cid has a visit, dee is staff


def test_explains_diagnostic_queries_compile_nothing(tmp_path, options):
    # without "a child": its diagnostic query ?calledByRule() is not of a plain shape, and would be
    # compiled with the declarations (this test's own text: no other test's explain builds it)
    files = {"q.drl": DRL.split('rule "a child"')[0] + "\n// explained\n"}
    engine = engine_with(tmp_path, "q", files, explain_prebuild=False, compile_cache_dir=str(tmp_path / "units"))
    explainer = build_explainer(engine, files)
    stats = explainer.queries.stats
    assert stats.rules_compiled == 0 and stats.rules_built >= 5, stats  # every diagnostic query plain
    # and the declarations they need are the deployed version's own unit, not compiled again
    assert (stats.units_compiled, stats.units_reused) == (1, 1), stats
    answer = engine.explain("q", FACTS)
    assert sorted(answer["fired"]) == sorted(f["rule"] for f in engine.fire("q", FACTS).fired)
