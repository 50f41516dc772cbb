"""Warming a freshly compiled rule set before it serves, so its first request is as fast as the rest.

Why: a new KieBase answers its first requests 10-200x slower than later ones (24 ms for a
1,000-rule set, 0.2 s at 10,000): its sessions' memory prototypes are built on first use, its
rules' new constraint and consequence classes run interpreted until the JIT has seen them a few
hundred times, and the Java helpers meet its declared types for the first time. Firing it on
sample facts before the swap moves that cost from the first customer to the deploy.

Sample facts are the rule set's ``examples.json`` fact lists when it has them (they exercise the
paths real requests take), the last requests the previous version served (``recent``: whatever
the rules' shapes, they reach the joins, accumulates and negations real requests reach, which
made-up facts stopped at the first constraint do not), a few requests made of the rules' own
literals (:func:`literal_facts`: each field takes the values the rules compare it with, so the
samples pass the alpha tests into the joins and consequences, whatever the rules' shapes), plus
one fact of each declared type with plain values. Firing errors (a then-part that throws on
made-up facts, a loop) are ignored: warming must never fail a deploy.

When to stop: rounds over all samples until a round is no longer 10% faster than the best round
before it, three times in a row. Why not "no slower than twice the best" per fire (the rule
before 2026-11-27): in a process the JIT has not warmed every fire is a little faster than the
last, which that rule read as settled after six fires; the first request after the swap then ran
interpreted code (10-26 ms of CPU for a 1,000-rule business set instead of ~1 ms warm). The budget
bounds it: ``budget_s``, which the engine raises for a build that took long (a cold build of many
new rules) to a share of the build's own time (``engine.warm_build_share``).
"""

from __future__ import annotations

import collections
import json
import logging
import re
import threading
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from gateway.base import priority
from gateway.engine import compiler
from gateway.engine.errors import EngineError

if TYPE_CHECKING:  # pragma: no cover
    from gateway.engine.build import CompiledRuleSet
    from gateway.engine.engine import Engine

log = logging.getLogger(__name__)

_lock = threading.Lock()
_PLAIN_VALUES = {"int": 1, "long": 1, "short": 1, "byte": 1, "double": 1.0, "float": 1.0, "boolean": False,
                 "String": "", "Integer": 1, "Long": 1, "Double": 1.0, "Float": 1.0, "Boolean": False,
                 "BigDecimal": 1, "Date": 0, "char": "a", "Character": "a"}
_TEXT_TYPES = {"String"}
_NUMBER_TYPES = {"int", "long", "short", "byte", "double", "float", "Integer", "Long", "Double", "Float", "BigDecimal"}
#: ``field <op> literal`` in a rule's text: what the literal samples take their values from.
_COMPARISON = re.compile(r'\b([A-Za-z_]\w*)\s*(==|!=|>=|<=|>|<)\s*("[^"\\\n]*"|-?\d+(?:\.\d+)?)(?![\w.])')
_PAST_BOUND = {">": 1, "<": -1}  # a strict bound's literal fails it: one step past it passes
_LITERALS_KEPT = 256  # distinct values per field name: enough to spread samples, bounded for huge sets
LITERAL_SAMPLES = 8  # requests made of the rules' literals
MIN_FIRES = 3  # fired whatever the budget (the first samples: examples, then recent requests)


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
    """Fires ``compiled`` on sample facts, in rounds over all samples, until it answers as fast
    as it is going to (three rounds in a row not 10% faster than the best), ``max_fires`` or
    ``budget_s`` (checked after each fire, once :data:`MIN_FIRES` ran); once per compiled rule
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
    samples.extend(json.dumps(facts) for facts in literal_facts(compiled.types, files or {}))
    samples.append(json.dumps(plain_facts(compiled.types)))
    stats.samples, stats.recent = len(samples), len(recent or ())
    compiled.warm_stats = stats
    started = time.perf_counter()
    deadline = started + budget_s
    best_round, stale = float("inf"), 0
    while stats.fires < max_fires and stale < 3 and (time.perf_counter() < deadline or stats.fires < MIN_FIRES):
        round_ms = 0.0
        for sample in samples:
            round_ms += _fire(compiled.runner, sample, fire_limit, stats)
            if time.perf_counter() > deadline and stats.fires >= MIN_FIRES:  # a slow set's round may not fit
                round_ms = float("inf")
                break
        stale = stale + 1 if round_ms > 0.9 * best_round else 0
        best_round = min(best_round, round_ms)
    stats.seconds = time.perf_counter() - started
    log.debug("warmed %s: %d fires in %.0f ms (first %.2f ms, last %.2f ms, %d refused)", compiled.hash[:12],
              stats.fires, stats.seconds * 1000, stats.first_ms, stats.last_ms, stats.errors)
    return stats


def _fire(runner: Any, sample: str, fire_limit: int, stats: WarmStats) -> float:
    """Fires one sample on ``runner``; its time in ms (counted in ``stats``)."""
    t = time.perf_counter()
    try:
        answer = str(runner.fire(sample, fire_limit, False, True))
        if not answer.startswith('{"ok":true'):
            stats.errors += 1
    except Exception:  # a Java exception out of a made-up fact: nothing to learn here
        stats.errors += 1
    elapsed = (time.perf_counter() - t) * 1000
    stats.first_ms = stats.first_ms or elapsed
    stats.last_ms = elapsed
    stats.fires += 1
    return elapsed


def field_literals(files: dict[str, str]) -> dict[str, list[Any]]:
    """Field name -> the distinct literals the rules' texts compare it with (``age >= 18``,
    ``region == "r5"``; ``amount > 250`` gives 251), in order of appearance, at most :data:`_LITERALS_KEPT` each. A plain scan
    of the text, not a parse: a miss only makes a warm-up sample less useful."""
    out: dict[str, dict[Any, None]] = {}
    for path, text in files.items():
        if not path.endswith((".drl", ".dslr")):
            continue
        for name, op, literal in _COMPARISON.findall(text):
            value: Any = literal[1:-1] if literal.startswith('"') else float(literal) + _PAST_BOUND.get(op, 0)
            kept = out.setdefault(name, {})
            if len(kept) < _LITERALS_KEPT:
                kept[value] = None
    return {name: list(values) for name, values in out.items()}


def literal_facts(types: dict[str, dict[str, str]], files: dict[str, str],
                  count: int = LITERAL_SAMPLES) -> list[list[dict[str, Any]]]:
    """``count`` requests of one fact of each declared type, each field taking in turn the
    literals the rules compare a field of its name with (a text field texts, a number field
    numbers); a field no rule compares with a literal keeps its plain value, the same in every
    type, so the rules' joins on such fields (``applicant == $id``) match. Why: a fresh rule set
    has served no request yet and may have no examples; facts that pass the alpha tests reach its
    joins, accumulates and consequences, whatever the rules' shapes."""
    literals = field_literals(files)
    out = []
    for k in range(count if literals else 0):
        facts = []
        for name, fields in types.items():
            fact: dict[str, Any] = {"type": name}
            for position, (field_name, type_name) in enumerate(fields.items()):
                if type_name not in _PLAIN_VALUES:
                    continue
                fact[field_name] = _PLAIN_VALUES[type_name]
                wanted = _TEXT_TYPES if type_name in _TEXT_TYPES else _NUMBER_TYPES
                values = [v for v in literals.get(field_name, ()) if (type(v) is str) == (wanted is _TEXT_TYPES)]
                if values and type_name in wanted:
                    value = values[(k * 7 + position) % len(values)]
                    fact[field_name] = int(value) if type_name in ("int", "long", "short", "byte", "Integer", "Long") else value
            facts.append(fact)
        out.append(facts)
    return out


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


class RecentRequests:
    """The facts (JSON) of the last stateless fires of each rule set in this process: the warm-up
    samples a new version of it gets from real traffic (see :func:`warm`)."""

    KEPT = 8  # per rule set
    MAX_BYTES = 64 * 1024  # a bigger request is not kept (warming is about paths, not volume)

    def __init__(self) -> None:
        self._kept: dict[str, collections.deque[str]] = {}

    def of(self, name: str) -> list[str]:
        """The last requests of ``name``, oldest first."""
        kept = self._kept.get(name)
        return list(kept) if kept else []

    def remember(self, name: str, facts_json: str) -> None:
        if len(facts_json) > self.MAX_BYTES:
            return
        kept = self._kept.get(name)
        if kept is None:
            kept = self._kept.setdefault(name, collections.deque(maxlen=self.KEPT))
        kept.append(facts_json)


class ProcessWarmUp:
    """The JIT warm-up of a fresh process (``Engine.warm_up``): builds a small rule set ``rounds``
    times (results thrown away) and fires each live rule set ``fires`` times with its
    ``examples.json`` facts (or none), so the JIT has compiled Drools' builder and firing paths
    before an author's first live edit or the first customer: the first firings in a fresh JVM are
    ~100x slower. (Not the live sets themselves: with incremental builds they would come from the
    cache, and compiling a 10,000-rule set twice at start would cost minutes.)"""

    def __init__(self, engine: Engine) -> None:
        self._engine = engine
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self, rounds: int, fires: int, background: bool) -> threading.Thread | None:
        """Run it, in a daemon thread when ``background`` (returned)."""
        if not background:
            self._work(rounds, fires)
            return None
        thread = threading.Thread(target=self._in_background, args=(rounds, fires), name="engine-warm-up", daemon=True)
        self._thread = thread
        thread.start()
        return thread

    def stop(self, timeout_s: float) -> None:
        """Ends a background warm-up at its next step and waits for it (a JVM call in progress
        cannot be interrupted), so shutting down never races it for the store or the JVM."""
        self._stop.set()
        thread = self._thread
        if thread is not None and thread.is_alive():
            thread.join(timeout_s)

    def _in_background(self, rounds: int, fires: int) -> None:
        priority.lower_this_thread()  # its own thread only: never the caller's
        self._work(rounds, fires)

    def _work(self, rounds: int, fires: int) -> None:
        try:
            compiler.warm_builder(rounds)
        except Exception:  # best effort, as below
            log.debug("warm-up of the builder failed", exc_info=True)
        try:
            infos = [] if self._stop.is_set() else self._engine.list_rulesets()
        except Exception:  # the store closed under us (shutdown) or is away: nothing to warm
            log.debug("warm-up could not list the rule sets", exc_info=True)
            infos = []
        for info in infos:
            if self._stop.is_set():
                return
            try:
                self._fire_examples(info.name, info.version, fires)
            except Exception:  # warm-up is best effort; real errors show on real use
                log.debug("warm-up of %s failed", info.name, exc_info=True)

    def _fire_examples(self, name: str, version: int, fires: int) -> None:
        samples = example_fact_sets(self._engine.version(name, version).files) or [[]]
        for k in range(fires):
            if self._stop.is_set():
                return
            try:  # no decision: warm-up is nothing to record
                self._engine.fire(name, samples[k % len(samples)], None, False, True, record=False)
            except EngineError:
                samples = [[]]
