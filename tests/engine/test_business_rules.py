"""Random business rule bases (bench/peers/business_rules.py: multi-constraint patterns, joins on
bound variables, accumulate count/sum/min/max, not/exists, ``in``, ``matches``, then-part calls
with widening and varargs; salience, agenda-group, no-loop, lock-on-active, date-effective and
date-expires) compiled at 1,000 rules for several seeds: every request fires exactly the rules a
Python model of their meaning says, as often as it says, with the texts their then-parts build —
also after a one-rule edit built incrementally (issue 30) — and all of them build as plain rules,
without generating Java (the cold build's speed must not depend on the generator)."""

from __future__ import annotations

import json
import sys
from collections import defaultdict
from pathlib import Path

import pytest

from gateway.engine import compiler, incremental
from gateway.engine.build import CompileOptions
from gateway.engine.results import encode_facts

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench" / "peers"))
from business_rules import CALLS, SHAPES, BusinessRules

RULES = 1000
REQUESTS = 4


@pytest.fixture()
def options(tmp_path) -> CompileOptions:
    incremental.reset()
    yield CompileOptions(cache_dir=str(tmp_path / "units"))
    incremental.reset()


def generator(seed: int, variants: dict[int, int] | None = None) -> BusinessRules:
    # small domains: a request of 4 applicants and 6 loans matches about one rule in two
    return BusinessRules(seed, RULES, regions=6, segments=3, purposes=3, domains=3, variants=variants or {})


def fired_texts(compiled, facts: list[dict]) -> dict[str, list[str]]:
    answer = json.loads(str(compiled.runner.fire(encode_facts(facts, 10_000), 10_000, False, True)))
    assert answer["ok"], answer
    out: dict[str, list[str]] = defaultdict(list)
    for action in answer["actions"]:
        out[action["rule"]].append(action["params"]["text"])
    return {rule: sorted(texts) for rule, texts in out.items()}


def expected_texts(rules: BusinessRules, facts: list[dict]) -> dict[str, list[str]]:
    return {rule: sorted(texts) for rule, texts in rules.expected(facts).items()}


def check(compiled, rules: BusinessRules) -> int:
    total = 0
    for k in range(REQUESTS):
        facts = rules.facts(k, applicants=4, loans=6)
        expected = expected_texts(rules, facts)
        got = fired_texts(compiled, facts)
        wrong = sorted(r for r in set(got) | set(expected) if got.get(r) != expected.get(r))
        assert not wrong, [(r, rules.rule(int(r[1:6])).attribute, got.get(r), expected.get(r)) for r in wrong[:10]]
        total += sum(len(t) for t in expected.values())
    return total


# Seed 1 (with its incremental edit) in the inner loop; the other random bases, a thousand rules
# compiled from scratch each, in the full run (make test): they are the soak of this model check.
@pytest.mark.parametrize("seed", [1, pytest.param(2, marks=pytest.mark.slow), pytest.param(3, marks=pytest.mark.slow)])
def test_a_random_thousand_rule_business_base_fires_as_its_model(seed, options):
    rules = generator(seed)
    shapes = {r.shape for r in rules.rules()}
    attributes = {r.attribute for r in rules.rules()}
    assert shapes == set(SHAPES) and len(attributes) == 8  # every shape and attribute (and none) drawn
    assert {r.p["call"] for r in rules.rules() if r.shape == "calls"} == set(range(len(CALLS)))  # every call form
    compiled = compiler.compile_files(rules.drl_files(), f"business{seed}", options)
    assert compiled.rule_count == RULES
    # every shape builds plain, the then-part calls with widening, boxing and varargs too (issue 30)
    assert compiled.stats.rules_built == RULES, compiled.stats
    assert compiler.plain_split(rules.drl_files())["plain"] == compiled.stats.rules_built
    fired = check(compiled, rules)
    assert fired > RULES // 2  # the requests reach a good share of the rules
    if seed == 1:  # a one-rule edit, built incrementally, fires as the edited model
        edited_rules = generator(seed, {517: 1})
        assert edited_rules.rule(517).drl != rules.rule(517).drl
        edited = compiler.compile_files(edited_rules.drl_files(), f"business{seed}", options)
        assert edited.stats.units_reused > 0
        check(edited, edited_rules)


def test_a_new_version_is_warmed_on_the_last_requests(tmp_path):
    """A rule base without examples.json: made-up facts stop at its first constraint, so the new
    version of a one-rule edit is also warmed on the facts of the last requests the previous one
    served (bounded), and reaches the joins and accumulates real requests reach before it serves."""
    from gateway.config import Settings
    from gateway.engine import Engine

    engine = Engine(Settings(data_dir=str(tmp_path / "data"), engine={"rules_dir": str(tmp_path / "rules"),
                                                                     "compile_cache_dir": str(tmp_path / "units")}))
    rules = BusinessRules(4, 60)
    engine.deploy("warmbiz", rules.drl_files())
    requests = [rules.facts(k) for k in range(Engine.RECENT_REQUESTS + 3)]
    for facts in requests:
        fired = engine.fire("warmbiz", facts)
        assert {r: len(t) for r, t in rules.expected(facts).items()} == _counts(fired.fired)
    kept = engine.recent_requests("warmbiz")
    assert [json.loads(k) for k in kept] == requests[3:]  # the last ones, oldest first
    edited = BusinessRules(4, 60, variants={30: 1})
    engine.deploy("warmbiz", edited.drl_files())
    _, compiled = engine.live_compiled("warmbiz")
    assert compiled.warm_stats.recent == Engine.RECENT_REQUESTS and compiled.warm_stats.fires >= 1
    facts = requests[-1]
    assert _counts(engine.fire("warmbiz", facts).fired) == {r: len(t) for r, t in edited.expected(facts).items()}


def _counts(fired: list[dict]) -> dict[str, int]:
    out: dict[str, int] = defaultdict(int)
    for f in fired:
        out[f["rule"]] += 1
    return dict(out)


def test_reused_sessions_fire_agenda_groups_in_the_order_of_fresh_ones(options):
    """Rules with ``agenda-group`` + ``auto-focus`` no longer stop session reuse (issue 30): a
    session emptied after a request fires the next one exactly as a session of its own — the same
    rules, texts and order. Before the Runner fired the emptied session, the old facts' deletions
    waited for the next request's fire and the groups then fired in another order (25 of these
    80 requests)."""
    from gateway.base import jvm

    rules = BusinessRules(1, 300, regions=6, segments=3, purposes=3, domains=3)
    assert sum(r.attribute == "agenda-group" for r in rules.rules()) >= 10
    compiled = compiler.compile_files(rules.drl_files(), "groups", options)
    assert compiled.runner.reusesSessions() and compiled.runner.settlesDeletions()
    runner_class = jvm.helper_class("Runner")
    for k in range(80):
        facts = encode_facts(rules.facts(k, applicants=4, loans=6), 10_000)
        reused = json.loads(str(compiled.runner.fire(facts, 10_000, False, True)))
        alone = json.loads(str(runner_class(compiled.kbase).fire(facts, 10_000, False, True)))
        assert reused["ok"] and reused == alone, k
