"""What every peer script shares: the simple 4-rule logic, the event stream, and the result format.

Why a shared module with no dependencies: the peers run in different virtualenvs (the project's
for the gateway, ``.venv-bench`` for durable_rules and drools-jpy), and each must see exactly the
same events and expect exactly the same firings. Every event matches exactly one of the 4 rules,
because drools-jpy (ansible-rulebook semantics) consumes an event at its first match; with
one match per event all three engines have the same meaning.
"""

from __future__ import annotations

import json
import sys
import time
from collections import Counter
from typing import Any, Callable

# The 4 rules, as (name, test on age and group_size). Each engine writes them in its own language.
RULES: list[tuple[str, Callable[[int, int], bool]]] = [
    ("child", lambda age, size: age < 13),
    ("adult alone", lambda age, size: 13 <= age < 65 and size == 1),
    ("adult group", lambda age, size: 13 <= age < 65 and size >= 2),
    ("senior", lambda age, size: age >= 65),
]


def event(i: int) -> dict[str, Any]:
    """The i-th visitor event: deterministic, spread over all four rules."""
    return {"type": "Visitor", "id": f"v{i}", "age": (i * 37) % 90, "group_size": 1 + (i * 7) % 4}


def expected_counts(n: int) -> dict[str, int]:
    """How often each rule must fire for events 0..n-1 (the correctness check of every peer)."""
    counts: Counter[str] = Counter()
    for i in range(n):
        e = event(i)
        for name, test in RULES:
            if test(e["age"], e["group_size"]):
                counts[name] += 1
    return dict(counts)


def rss_mb() -> dict[str, float]:
    """Current and peak resident set size of this process, in MB (Linux /proc)."""
    out = {}
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(("VmRSS:", "VmHWM:")):
                key = "rss_mb" if line.startswith("VmRSS") else "peak_rss_mb"
                out[key] = round(int(line.split()[1]) / 1024, 1)
    return out


def timed_rate(n: int, seconds: float) -> float:
    return n / seconds if seconds > 0 else float("inf")


ROUNDS = 3
WARMUP_ROUNDS = 3  # untimed rounds before the timed ones, the same for every engine 


def warm_up(run_round: Callable[[], int], rounds: int = WARMUP_ROUNDS) -> None:
    """Runs ``run_round`` untimed, so each engine is measured warm (the JVM's JIT needs ~100k events)."""
    for _ in range(rounds):
        run_round()


def best_of(run_round: Callable[[], int], rounds: int = ROUNDS) -> dict[str, float]:
    """Runs ``run_round`` (which returns how many events it handled) several times.

    Why best-of: the machine is shared and noisy; the best round is the closest to what the engine
    can do, the median shows the spread. Every engine is measured the same way.
    """
    rates = []
    for _ in range(rounds):
        start = time.perf_counter()
        n = run_round()
        rates.append(timed_rate(n, time.perf_counter() - start))
    return {"best": max(rates), "median": sorted(rates)[len(rates) // 2]}


class Clock:
    """perf_counter stopwatch."""

    def __enter__(self) -> "Clock":
        self.start = time.perf_counter()
        return self

    def __exit__(self, *exc: object) -> None:
        self.seconds = time.perf_counter() - self.start


def emit(result: dict[str, Any]) -> None:
    """The one line the orchestrator reads: JSON on stdout, prefixed so log noise cannot confuse it."""
    sys.stdout.write("BENCH-RESULT " + json.dumps(result) + "\n")
    sys.stdout.flush()
