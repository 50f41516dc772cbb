"""Peer: durable_rules (a rules engine with a C core and Python consequences), run in .venv-bench.

Usage: .venv-bench/bin/python bench/peers/durable_rules_peer.py N
One at a time: ``post`` per event. Batched: ``post_batch`` with lists of 1000 events.
durable_rules drops a message whose "id" it has already seen (MessageObservedException), so each
round gives its events fresh ids; the rules never look at the id.
"""

from __future__ import annotations

import sys
from collections import Counter

from common import Clock, best_of, warm_up, emit, event, expected_counts, rss_mb

BATCH = 1000


def define(name: str, counts: Counter) -> None:
    """The 4 rules of common.RULES in durable_rules' Python DSL; each consequence counts its firing."""
    from durable.lang import m, ruleset, when_all

    def count(rule: str):
        def consequence(c):
            counts[rule] += 1
        return consequence

    with ruleset(name):
        when_all(m.age < 13)(count("child"))
        when_all((m.age >= 13) & (m.age < 65) & (m.group_size == 1))(count("adult alone"))
        when_all((m.age >= 13) & (m.age < 65) & (m.group_size >= 2))(count("adult group"))
        when_all(m.age >= 65)(count("senior"))


def main(n: int) -> None:
    from durable.lang import post, post_batch

    single: Counter[str] = Counter()
    batched: Counter[str] = Counter()
    with Clock() as setup:
        define("visitors_single", single)
        define("visitors_batch", batched)
    events = [event(i) for i in range(n)]
    checks: list[bool] = []
    want = expected_counts(n)
    rounds = iter(range(1_000_000))

    def one_round() -> int:
        single.clear()
        r = next(rounds)
        for e in events:
            post("visitors_single", dict(e, id=f"{r}-{e['id']}"))
        checks.append(dict(single) == want)
        return n

    def batch_round() -> int:
        batched.clear()
        r = next(rounds)
        for k in range(0, n, BATCH):
            post_batch("visitors_batch", [dict(e, id=f"{r}-{e['id']}") for e in events[k : k + BATCH]])
        checks.append(dict(batched) == want)
        return n

    warm_up(one_round)
    one = best_of(one_round)
    warm_up(batch_round)
    batch = best_of(batch_round)
    emit({"peer": "durable_rules", "events": n, "one_at_a_time_per_s": one, "batched_per_s": batch,
          "setup_s": setup.seconds, "correct": all(checks), "checks": checks, "counts": dict(single), "batch_counts": dict(batched), **rss_mb()})

if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 20000)
