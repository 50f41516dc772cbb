"""The gateway's engine (Drools 8.31 in-process through JPype), measured through its public API.

Usage (project venv): .venv/bin/python bench/peers/gateway_peer.py MODE [N]
  simple N    the simple 4-rule logic of common.RULES: events one at a time (synchronous push and the
              pipelined EventFeed) and batched
  reception   the 32-rule teahouse set: fire latency, warm redeploy, RSS
  cold        a fresh JVM: JVM start and the first compile of the 32-rule set
Each mode runs in a process of its own (the orchestrator, bench/engine_bench.py, starts them).
"""

from __future__ import annotations

import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

from common import Clock, best_of, warm_up, emit, event, expected_counts, rss_mb

ROOT = Path(__file__).resolve().parents[2]
RECEPTION = ROOT / "rules" / "drl" / "reception"
BATCH = 10_000

# common.RULES in DRL. Visitors are events that expire 1 s (of pseudo time) after they happen,
# so a long stream keeps working memory bounded, as a real sensor stream must.
SIMPLE_DRL = """package org.printeps.bench;
import org.printeps.gateway.Actions;
global Actions actions;

declare Visitor
    @role(event)
    @expires(1s)
    id : String
    age : int
    group_size : int
end

rule "child" when Visitor(age < 13) then actions.say("pepper", "Hello, little one!"); end
rule "adult alone" when Visitor(age >= 13, age < 65, group_size == 1) then actions.say("pepper", "Welcome."); end
rule "adult group" when Visitor(age >= 13, age < 65, group_size >= 2) then actions.say("pepper", "Welcome, all of you."); end
rule "senior" when Visitor(age >= 65) then actions.say("pepper", "Welcome, please take a seat."); end
"""


def new_engine():
    from gateway.config import Settings
    from gateway.engine import Engine

    data = tempfile.mkdtemp(prefix="printeps-bench-")
    return Engine(Settings(data_dir=data, engine={"rules_dir": str(Path(data) / "none")}))


def percentile(samples: list[float], q: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


# --------------------------------------------------------------------------- simple 4 rules


def simple(n: int) -> None:
    engine = new_engine()
    engine.deploy("visitors", {"visitors.drl": SIMPLE_DRL})
    events = [event(i) for i in range(n)]
    want = expected_counts(n)
    checks: list[bool] = []
    one = _one_at_a_time(engine, events, want, checks)
    fed = _feed(engine, events, want, checks)
    batch = _batched(engine, events * 4, checks)  # 4 copies: a round long enough to time
    stateless = _stateless_batches(engine, events * 2)
    emit({"peer": "gateway", "events": n, "one_at_a_time_per_s": one, "feed_per_s": fed, "batched_per_s": batch,
          "stateless_batch_per_s": stateless, "correct": all(checks), **rss_mb()})


def _one_at_a_time(engine, events: list[dict], want: dict[str, int], checks: list[bool]) -> dict[str, float]:
    """One event in, its answer out (``session.push``: insert + fire in one JVM call), counting the
    fired rules the answer names (like a callback)."""
    session = engine.open_session("visitors", record_facts=False)
    clock = [0]

    def one_round() -> int:
        counts: dict[str, int] = {}
        for e in events:
            clock[0] += 1
            for f in session.push([e], clock[0]).fired:
                counts[f["rule"]] = counts.get(f["rule"], 0) + 1
        checks.append(counts == want)
        return len(events)

    warm_up(one_round)  # let the JIT compile the Drools and helper paths
    rate = best_of(one_round)
    session.close()
    return rate


def _feed(engine, events: list[dict], want: dict[str, int], checks: list[bool]) -> dict[str, float]:
    """One event per ``EventFeed.submit`` call; each event is inserted and fired on its own and its
    answer (the ``FireResult``) reaches a callback that counts the fired rules. A round ends when
    every answer has been delivered (``flush``)."""
    session = engine.open_session("visitors", record_facts=False)
    counts: dict[str, int] = {}
    errors: list[Exception] = []

    def on_result(result) -> None:
        for f in result.fired:
            counts[f["rule"]] = counts.get(f["rule"], 0) + 1

    feed = session.feed(on_result, on_error=errors.append)
    clock = [0]

    def one_round() -> int:
        counts.clear()
        for e in events:
            clock[0] += 1
            feed.submit([e], clock[0])
        feed.flush()
        checks.append(counts == want and not errors)
        return len(events)

    warm_up(one_round)
    rate = best_of(one_round)
    feed.close()
    session.close()
    return rate


def _batched(engine, events: list[dict], checks: list[bool]) -> dict[str, float]:
    """BATCH events per call (JSON encoding with the engine's encoder included); then the clock
    moves on so they expire."""
    from gateway.engine.results import encode_facts

    session = engine.open_session("visitors", record_facts=False)
    chunks = [events[k : k + BATCH] for k in range(0, len(events), BATCH)]

    def one_round() -> int:
        fired = 0
        for chunk in chunks:
            fired += session.insert_and_fire_count(encode_facts(chunk, BATCH))
            session.advance_clock(2000)
        checks.append(fired == len(events))  # each event matches exactly one rule
        return len(events)

    warm_up(one_round)  # the JIT needs a few hundred thousand facts
    rate = best_of(one_round)
    session.close()
    return rate


def _stateless_batches(engine, events: list[dict], size: int = 1000) -> dict[str, float]:
    """Engine.fire with ``size`` facts per request, actions returned (facts not echoed back)."""
    chunks = [events[k : k + size] for k in range(0, len(events), size)]

    def one_round() -> int:
        for chunk in chunks:
            engine.fire("visitors", chunk, return_facts=False, record_facts=False)
        return len(events)

    one_round()  # warm-up
    return best_of(one_round)


# --------------------------------------------------------------------------- reception (32 rules)


def reception_request() -> tuple[str, list[dict]]:
    """The first 5-fact example of rules/drl/reception/examples.json."""
    examples = json.loads((RECEPTION / "examples.json").read_text(encoding="utf-8"))
    for ex in examples:
        if len(ex["facts"]) == 5:
            return ex["name"], ex["facts"]
    raise SystemExit("no 5-fact example in rules/drl/reception/examples.json")


def reception(requests: int) -> None:
    from gateway.engine.ruleset import read_folder

    engine = new_engine()
    files = read_folder(RECEPTION)
    with Clock() as first:
        engine.deploy("reception", files)
    rules = engine.rule_count("reception")
    name, facts = reception_request()
    result = engine.fire("reception", facts)
    lat = {}
    for label, kwargs in (("full", {}), ("lean", {"return_facts": False, "record_facts": False})):
        for _ in range(2000):
            engine.fire("reception", facts, **kwargs)
        samples, cpu = [], []
        for _ in range(requests):
            c = time.thread_time()
            t = time.perf_counter()
            engine.fire("reception", facts, **kwargs)
            samples.append((time.perf_counter() - t) * 1000)
            cpu.append((time.thread_time() - c) * 1000)
        # CPU time of this thread (JPype runs the Java side in it): what the request costs when the
        # shared machine does not take the core away in the middle of it.
        lat[label] = {"p50_ms": percentile(samples, 0.50), "p99_ms": percentile(samples, 0.99),
                      "mean_ms": statistics.fmean(samples), "max_ms": max(samples),
                      "cpu_p50_ms": percentile(cpu, 0.50), "cpu_p99_ms": percentile(cpu, 0.99),
                      "slower_than_1ms": sum(1 for x in samples if x >= 1.0)}
    redeploys = []
    for k in range(10):  # a changed comment changes the content hash, so nothing comes from the cache
        changed = dict(files)
        changed["types.drl"] = files["types.drl"] + f"\n// bench redeploy {k} {time.time()}\n"
        with Clock() as c:
            engine.deploy("reception", changed)
        if k >= 5:  # the first redeploys still warm up the compiler's JIT: not counted
            redeploys.append(c.seconds)
    emit({"peer": "gateway", "ruleset_rules": rules, "example": name, "facts": len(facts),
          "fired": result.fire_count, "actions": len(result.actions), "requests": requests,
          "latency": lat, "first_deploy_s": first.seconds,
          "redeploy_s": {"median": statistics.median(redeploys), "max": max(redeploys), "all": redeploys},
          **rss_mb()})


def cold() -> None:
    """JVM start and the first compile of the 32-rule set, in a process that never ran Java."""
    from gateway.base import jvm
    from gateway.engine.ruleset import read_folder

    t0 = time.perf_counter()
    import jpype  # noqa: F401  (import cost belongs to the start)
    engine = new_engine()
    with Clock() as start:
        jvm.start(engine.settings.jvm)
    with Clock() as compile_:
        engine.deploy("reception", read_folder(RECEPTION))
    emit({"peer": "gateway", "jvm_start_s": start.seconds, "first_compile_s": compile_.seconds,
          "total_s": time.perf_counter() - t0, **rss_mb()})


if __name__ == "__main__":
    mode = sys.argv[1] if len(sys.argv) > 1 else "reception"
    arg = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    if mode == "simple":
        simple(arg or 100_000)
    elif mode == "reception":
        reception(arg or 5000)
    elif mode == "cold":
        cold()
    else:
        raise SystemExit(f"unknown mode {mode!r}: simple | reception | cold")
