"""Peer: durable_rules on the growth bench's generated rules (run in .venv-bench).

Usage: .venv-bench/bin/python bench/peers/growth_durable_peer.py N [SHAPES]
durable_rules has joins but no accumulate, so it could load the range, equality and join rules of
the set (SHAPES=range,equality,join2,join3). In practice 2.0.28 breaks on them beyond a few dozen
rules (``free(): invalid pointer``, or error 303 ERR_MAX_STACK_SIZE when facts are asserted), so the
bench gives it the equality rules (SHAPES=equality, the default: 1 in 5) and records the crash of
the full shape set separately. It is checked to fire exactly the rules it loaded as expected. A
request asserts the 5 facts into a session of its own (``sid``) and deletes it after; a one-rule
change defines the whole ruleset again under a new name (durable_rules cannot change a defined
ruleset).
"""

from __future__ import annotations

import statistics
import sys
import time

from common import Clock, emit, rss_mb
from growth_rules import BAND, expected_firings, kind, params, rule_name, sample_facts

LOADED: tuple[str, ...] = ("equality",)
WARM, REQUESTS = 300, 2000


def define(name: str, n: int, fired: list, variants: dict[int, int] | None = None) -> None:
    from durable.lang import c, m, ruleset, when_all

    variants = variants or {}
    with ruleset(name):
        for i in range(n):
            k = kind(i)
            if k not in LOADED:
                continue
            p = params(i + variants.get(i, 0) * 7919)
            if k == "range":
                conds = [(m.type == "Order") & (m.category == p["category"]) & (m.amount >= p["lo"])
                         & (m.amount < p["lo"] + BAND) & (m.quantity >= p["q"])]
            elif k == "equality":
                conds = [(m.type == "Customer") & (m.tier == p["tier"]) & (m.region == p["region"])]
            elif k == "join2":
                conds = [c.first << ((m.type == "Customer") & (m.tier == p["tier"]) & (m.region == p["region"])),
                         c.second << ((m.type == "Order") & (m.customer == c.first.id) & (m.category == p["category"])
                                      & (m.amount > p["amount"]))]
            else:
                conds = [c.first << ((m.type == "Customer") & (m.region == p["region"]) & (m.age > p["age"])),
                         c.second << ((m.type == "Order") & (m.customer == c.first.id) & (m.category == p["category"])),
                         c.third << ((m.type == "Product") & (m.category == c.second.category) & (m.price < p["price"]))]
            when_all(*conds)(_consequence(rule_name(i), fired))


def _consequence(label: str, fired: list):
    """A one-argument action (with two, durable_rules takes it for an asynchronous one)."""
    def action(c) -> None:
        fired.append(label)
    return action


def _first_use(name: str) -> None:
    from durable.engine import MessageNotHandledException
    from durable.lang import assert_fact, delete_state

    try:
        assert_fact(name, dict(sample_facts(0)[0], sid="setup"))
    except MessageNotHandledException:
        pass
    delete_state(name, "setup")


def main(n: int) -> None:
    from durable.engine import MessageNotHandledException
    from durable.lang import assert_fact, delete_state

    fired: list[str] = []
    with Clock() as setup:  # durable_rules builds a ruleset on its first use: one request is part of setup
        define("growth0", n, fired)
        _first_use("growth0")
    redeploys = []
    for k in range(3):
        with Clock() as again:
            define(f"growth{k + 1}", n, [], {(n * (2 * k + 1)) // 6: k + 1})
            _first_use(f"growth{k + 1}")
        redeploys.append(again.seconds)
    facts = [sample_facts(k) for k in range(50)]
    sid = [0]

    def request(batch: list[dict]) -> list[str]:
        fired.clear()
        sid[0] += 1
        session = str(sid[0])
        for fact in batch:  # one at a time: a fact no rule wants raises, and must not stop the others
            try:
                assert_fact("growth0", dict(fact, sid=session))
            except MessageNotHandledException:
                pass
        out = list(fired)
        delete_state("growth0", session)
        return out

    correct = True
    for k in range(10):
        want = {r: c for r, c in expected_firings(n, facts[k]).items() if r.rsplit(" ", 1)[1] in LOADED}
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
    emit({"peer": "durable_rules", "rules": n, "rules_loaded": sum(1 for i in range(n) if kind(i) in LOADED),
          "setup_s": setup.seconds, "redeploy_s": statistics.median(redeploys),
          "fire": {"p50_ms": samples[len(samples) // 2], "p99_ms": samples[int(len(samples) * 0.99)],
                   "requests": REQUESTS}, "correct": correct, **rss_mb()})


if __name__ == "__main__":
    if len(sys.argv) > 2:
        LOADED = tuple(sys.argv[2].split(","))
    main(int(sys.argv[1]))
