"""Warming a freshly compiled rule set before it serves, so its first request is as fast as the rest.

Why: a new KieBase answers its first requests 10-200x slower than later ones (24 ms for a
1,000-rule set, 0.2 s at 10,000): its sessions' memory prototypes are built on first use, its
rules' new constraint and consequence classes run interpreted until the JIT has seen them a few
hundred times, and the Java helpers meet its declared types for the first time. Firing it on
sample facts before the swap moves that cost from the first customer to the deploy.

Sample facts are the rule set's ``examples.json`` fact lists when it has them (they exercise the
paths real requests take), the last requests the previous version served (``recent``: whatever
the rules' shapes, they reach the joins, accumulates and negations real requests reach, which
made-up facts stopped at the first constraint do not), plus one fact of each declared type with
plain values. Firing errors
(a then-part that throws on made-up facts, a loop) are ignored: warming must never fail a deploy.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from gateway.engine.build import CompiledRuleSet

log = logging.getLogger(__name__)

_lock = threading.Lock()
_PLAIN_VALUES = {"int": 1, "long": 1, "short": 1, "byte": 1, "double": 1.0, "float": 1.0, "boolean": False,
                 "String": "", "Integer": 1, "Long": 1, "Double": 1.0, "Float": 1.0, "Boolean": False,
                 "BigDecimal": 1, "Date": 0, "char": "a", "Character": "a"}


@dataclass
class WarmStats:
    fires: int = 0
    errors: int = 0
    first_ms: float = 0.0
    last_ms: float = 0.0
    seconds: float = 0.0
    samples: int = 0  # fact lists fired
    recent: int = 0  # of which the last requests the previous version served


def warm(compiled: CompiledRuleSet, files: dict[str, str] | None = None, budget_s: float = 0.25,
         max_fires: int = 300, fire_limit: int = 1000, recent: list[str] | None = None) -> WarmStats:
    """Fires ``compiled`` on sample facts until it answers as fast as it is going to (the last
    rounds no slower than twice the best), ``max_fires`` or ``budget_s``; once per compiled rule
    set (later calls return at once).

    After a one-rule edit little is new (the other rules' classes are the ones the JIT already
    knows): a few rounds do. After a cold build every rule's classes are new: it takes the budget."""
    stats = WarmStats()
    with _lock:
        if compiled.warmed:
            return stats
        compiled.warmed = True
    samples = [json.dumps(facts) for facts in example_fact_sets(files or {})]
    samples.extend(recent or ())
    samples.append(json.dumps(plain_facts(compiled.types)))
    stats.samples, stats.recent = len(samples), len(recent or ())
    compiled.warm_stats = stats
    started = time.perf_counter()
    runner = compiled.runner
    best = [float("inf")] * len(samples)  # per sample: requests differ in cost, compare like with like
    settled = 0
    while stats.fires < max_fires:
        k = stats.fires % len(samples)
        t = time.perf_counter()
        try:
            answer = str(runner.fire(samples[k], fire_limit, False, True))
            if not answer.startswith('{"ok":true'):
                stats.errors += 1
        except Exception:  # a Java exception out of a made-up fact: nothing to learn here
            stats.errors += 1
        elapsed = (time.perf_counter() - t) * 1000
        stats.first_ms = stats.first_ms or elapsed
        stats.last_ms = elapsed
        stats.fires += 1
        settled = settled + 1 if elapsed <= 2 * best[k] else 0
        best[k] = min(best[k], elapsed)
        if settled >= 3 * len(samples) or time.perf_counter() - started > budget_s:
            break
    stats.seconds = time.perf_counter() - started
    log.debug("warmed %s: %d fires in %.0f ms (first %.2f ms, last %.2f ms, %d refused)", compiled.hash[:12],
              stats.fires, stats.seconds * 1000, stats.first_ms, stats.last_ms, stats.errors)
    return stats


def example_fact_sets(files: dict[str, str]) -> list[list[dict[str, Any]]]:
    """The fact lists of a rule set's ``examples.json`` ([{"name", "facts"}]), [] if none/unreadable."""
    try:
        examples = json.loads(files.get("examples.json", "[]"))
        return [e["facts"] for e in examples if isinstance(e, dict) and isinstance(e.get("facts"), list)]
    except (ValueError, TypeError, KeyError):
        return []


def plain_facts(types: dict[str, dict[str, str]]) -> list[dict[str, Any]]:
    """One fact of each declared type, every field with a plain value of its type (nested declared
    types and collections are left out)."""
    facts = []
    for name, fields in types.items():
        fact: dict[str, Any] = {"type": name}
        for field_name, type_name in fields.items():
            if type_name in _PLAIN_VALUES:
                fact[field_name] = _PLAIN_VALUES[type_name]
        facts.append(fact)
    return facts
