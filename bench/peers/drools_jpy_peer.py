"""Peer: drools-jpy (ansible-rulebook's Drools binding, rules as a JSON AST), run in .venv-bench.

Usage: JAVA_HOME=<a Java 17+ home> .venv-bench/bin/python bench/peers/drools_jpy_peer.py N
Events go one at a time through ``Ruleset.assert_event`` (the library's own call; ``post`` would
add a forced ``System.gc()`` every 1000 events). drools-jpy has no batch insert, so no batch figure.
"""

from __future__ import annotations

import json
import sys
from collections import Counter

from common import Clock, best_of, warm_up, emit, event, expected_counts, rss_mb


def _cmp(op: str, field: str, value: int) -> dict:
    return {op: {"lhs": {"Event": field}, "rhs": {"Integer": value}}}


def _and(*exprs: dict) -> dict:
    out = exprs[0]
    for e in exprs[1:]:
        out = {"AndExpression": {"lhs": out, "rhs": e}}
    return out


# The 4 rules of common.RULES in the rulebook AST.
CONDITIONS = {
    "child": _cmp("LessThanExpression", "age", 13),
    "adult alone": _and(_cmp("GreaterThanOrEqualToExpression", "age", 13), _cmp("LessThanExpression", "age", 65),
                        _cmp("EqualsExpression", "group_size", 1)),
    "adult group": _and(_cmp("GreaterThanOrEqualToExpression", "age", 13), _cmp("LessThanExpression", "age", 65),
                        _cmp("GreaterThanOrEqualToExpression", "group_size", 2)),
    "senior": _cmp("GreaterThanOrEqualToExpression", "age", 65),
}


def ruleset_ast() -> dict:
    return {
        "name": "visitors",
        "hosts": ["all"],
        "sources": [{"EventSource": {"name": "bench", "source_name": "bench", "source_args": {}, "source_filters": []}}],
        "rules": [
            {"Rule": {"name": name, "enabled": True, "condition": {"AllCondition": [cond]},
                      "action": {"Action": {"action": "debug", "action_args": {}}}}}
            for name, cond in CONDITIONS.items()
        ],
    }


def main(n: int) -> None:
    from drools.rule import Rule
    from drools.ruleset import Ruleset

    counts: Counter[str] = Counter()
    with Clock() as setup:
        rs = Ruleset(name="visitors", serialized_ruleset=json.dumps(ruleset_ast()))
        for name in CONDITIONS:
            rs.add_rule(Rule(name, lambda match, name=name: counts.__setitem__(name, counts[name] + 1)))
    events = [event(i) for i in range(n)]
    rounds: list[dict[str, int]] = []

    def one_round() -> int:
        counts.clear()
        for e in events:
            rs.assert_event(json.dumps(e))
        rounds.append(dict(counts))
        return n

    warm_up(one_round)
    rate = best_of(one_round)
    ok = all(r == expected_counts(n) for r in rounds)
    emit({"peer": "drools-jpy", "events": n, "one_at_a_time_per_s": rate,
          "setup_s": setup.seconds, "correct": ok, "counts": rounds[-1], **rss_mb()})
    rs.end_session()


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20000)
