"""Peer: drools-jpy (ansible-rulebook's Drools binding; rules as a JSON AST) on the growth bench's
generated rules (run in .venv-bench with JAVA_HOME set to a Java 17+).

Usage: JAVA_HOME=... .venv-bench/bin/python bench/peers/growth_drools_jpy_peer.py N
The rulebook AST has conditions on facts and joins between them but no accumulate: it loads the
range, equality and 2-/3-pattern join rules of the set (4 of every 5), checked to fire exactly those
as expected. A request asserts the 5 facts (``assert_fact``, one call each: there is no batch call)
and retracts them after; a one-rule change builds the whole ruleset again (the AST is a whole).
"""

from __future__ import annotations

import json
import statistics
import sys
import time

from common import Clock, emit, rss_mb
from growth_rules import BAND, expected_firings, kind, params, rule_name, sample_facts

LOADED = ("range", "equality", "join2", "join3")
WARM, REQUESTS = 300, 2000


def _value(v) -> dict:
    if isinstance(v, str):
        return {"String": v}
    if isinstance(v, float):
        return {"Float": v}
    return {"Integer": v}


def _cmp(op: str, field: str, value) -> dict:
    rhs = {"Facts": value[1:]} if isinstance(value, str) and value.startswith("@") else _value(value)
    return {op: {"lhs": {"Fact": field}, "rhs": rhs}}


def _and(*exprs: dict) -> dict:
    out = exprs[0]
    for e in exprs[1:]:
        out = {"AndExpression": {"lhs": out, "rhs": e}}
    return out


EQ, GE, GT, LT = "EqualsExpression", "GreaterThanOrEqualToExpression", "GreaterThanExpression", "LessThanExpression"


def condition(i: int, variants: dict[int, int]) -> list[dict]:
    p = params(i + variants.get(i, 0) * 7919)
    k = kind(i)
    if k == "range":
        return [_and(_cmp(EQ, "type", "Order"), _cmp(EQ, "category", p["category"]), _cmp(GE, "amount", p["lo"]),
                     _cmp(LT, "amount", p["lo"] + BAND), _cmp(GE, "quantity", p["q"]))]
    if k == "equality":
        return [_and(_cmp(EQ, "type", "Customer"), _cmp(EQ, "tier", p["tier"]), _cmp(EQ, "region", p["region"]))]
    if k == "join2":
        return [_and(_cmp(EQ, "type", "Customer"), _cmp(EQ, "tier", p["tier"]), _cmp(EQ, "region", p["region"])),
                _and(_cmp(EQ, "type", "Order"), _cmp(EQ, "customer", "@m_0.id"), _cmp(EQ, "category", p["category"]),
                     _cmp(GT, "amount", p["amount"]))]
    return [_and(_cmp(EQ, "type", "Customer"), _cmp(EQ, "region", p["region"]), _cmp(GT, "age", p["age"])),
            _and(_cmp(EQ, "type", "Order"), _cmp(EQ, "customer", "@m_0.id"), _cmp(EQ, "category", p["category"])),
            _and(_cmp(EQ, "type", "Product"), _cmp(EQ, "category", "@m_1.category"), _cmp(LT, "price", p["price"]))]


def build(name: str, n: int, fired: list, variants: dict[int, int] | None = None):
    from drools.rule import Rule
    from drools.ruleset import Ruleset

    variants = variants or {}
    loaded = [i for i in range(n) if kind(i) in LOADED]
    ast = {"name": name, "hosts": ["all"],
           "sources": [{"EventSource": {"name": "bench", "source_name": "bench", "source_args": {}, "source_filters": []}}],
           "rules": [{"Rule": {"name": rule_name(i), "enabled": True, "condition": {"AllCondition": condition(i, variants)},
                               "action": {"Action": {"action": "debug", "action_args": {}}}}} for i in loaded]}
    rs = Ruleset(name=name, serialized_ruleset=json.dumps(ast))
    for i in loaded:
        label = rule_name(i)
        rs.add_rule(Rule(label, lambda _m, label=label: fired.append(label)))
    return rs


def main(n: int) -> None:
    fired: list[str] = []
    with Clock() as setup:
        rs = build("growth0", n, fired)
    redeploys = []
    for k in range(3):
        with Clock() as again:
            other = build(f"growth{k + 1}", n, [], {(n * (2 * k + 1)) // 6: k + 1})
        redeploys.append(again.seconds)
        other.end_session()
    facts = [[json.dumps(f) for f in sample_facts(k)] for k in range(50)]

    def request(batch: list[str]) -> list[str]:
        fired.clear()
        for fact in batch:
            rs.assert_fact(fact)
        out = list(fired)
        for fact in batch:
            rs.retract_fact(fact)
        return out

    correct = True
    for k in range(10):
        want = {r: c for r, c in expected_firings(n, sample_facts(k)).items() if r.rsplit(" ", 1)[1] in LOADED}
        got: dict[str, int] = {}
        for rule in request(facts[k]):
            got[rule] = got.get(rule, 0) + 1
        correct = correct and got == want
    for k in range(WARM):
        request(facts[k % 50])
    samples = []
    for k in range(REQUESTS):
        t = time.perf_counter()
        request(facts[k % 50])
        samples.append((time.perf_counter() - t) * 1000)
    samples.sort()
    emit({"peer": "drools-jpy", "rules": n, "rules_loaded": sum(1 for i in range(n) if kind(i) in LOADED),
          "setup_s": setup.seconds, "redeploy_s": statistics.median(redeploys),
          "fire": {"p50_ms": samples[len(samples) // 2], "p99_ms": samples[int(len(samples) * 0.99)], "requests": REQUESTS},
          "correct": correct, **rss_mb()})
    rs.end_session()


if __name__ == "__main__":
    main(int(sys.argv[1]))
