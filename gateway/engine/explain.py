"""Explain: why each rule of a version fired on some facts, or which condition stopped it.

Drools answers "what fired" but not "why not". A rule's conditions are text the gateway owns,
though (DRL, the DRL a .dslr expands to, the DRL a decision table becomes), so the question is
asked to Drools itself, as diagnostic queries compiled with the rule set through the executable
model (see /work/shared/design/explain-and-durable-sessions.md):

1. For a rule with top-level conditions C1 … Cn, the query ``C1 … Ck`` for each k: the first k
   whose query has no row is the condition that stopped the rule (earlier bindings are kept, since
   the query holds the conditions before it).
2. Inside that condition's pattern ``Type(c1, …, cm)``, the queries ``C1 … Ck-1, $f : Type(c1 … cj)``:
   every candidate fact of the type, and how many of the constraints in order it passes. The fact
   that passes most came closest; the constraint after them is the one that failed, and its field's
   value in that fact is what to show ("language is "fr", the rule wants "en"").
3. ``not X``: the X facts that exist; ``exists X``: as a pattern (none passes); a value ``from
   accumulate``: the accumulated value against its constraint; ``from expr``: the items of the source.

Queries run in a throwaway session holding the facts after the rules fired (the then-parts'
``modify``s included) — nothing is recorded, nothing reaches a robot. Generating and compiling the
queries costs a build: it is done once per version (or draft text) and cached, off the serving path.
Conditions are shown in the author's words: the .dslr lines (sentence and ``-`` lines) a condition
was expanded from, or the decision table cell its DRL line came from.

The module is the entry point (:func:`explain`, the cache of built explainers, the build);
:mod:`gateway.engine.explain_plan` reads the rules and writes the queries,
:mod:`gateway.engine.explain_reasons` turns the queries' rows into reasons.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from collections import OrderedDict, deque
from dataclasses import dataclass
from typing import Any

from gateway.base import priority
from gateway.engine import warmup
from gateway.engine.errors import CompileError, CompileFailed, EngineError
from gateway.engine.explain_plan import RulePlan, plan_rules, query_files
from gateway.engine.explain_reasons import Run, ThrowawaySession, explain_rule, prefetch
from gateway.engine.ruleset import MAX_FILES, MAX_TOTAL_BYTES, content_hash

log = logging.getLogger(__name__)

__all__ = ["ExplainBusy", "ExplainCache", "Explainer", "ThrowawaySession", "build", "explain"]

CACHE_SIZE = 8
MAX_WAITING = 8  # explanations queued or running per process; more are refused (429)


@dataclass
class Explainer:
    """A version's (or draft's) rules compiled, and its types compiled with the diagnostic queries."""

    plans: list[RulePlan]
    rules: Any  # the rule set compiled (shared with the version's own build)
    queries: Any  # the declarations (rules left out) with the queries


def _broken_rules(errors: list[CompileError], files: dict[str, str], plans: list[RulePlan]) -> set[int]:
    """The rules whose queries the compile errors point at (by the query name above the error's line)."""
    broken: set[int] = set()
    for err in errors:
        text = files.get(err.file)
        if text is None:
            continue
        before = text.split("\n")[:max(err.line, 1)]
        for line in reversed(before):
            match = re.match(r'\s*query "why__(\d+)__', line)
            if match:
                broken.add(int(match.group(1)))
                break
    return broken


def declarations(sources: list[tuple[Any, Any]]) -> dict[str, str]:
    """The rule set's DRL without its rules (types, functions, globals, queries), one file per source:
    the queries run on their own build of these, so the rules are not compiled again for them. A
    .drl file keeps its name, so that these are the rule set's own declarations unit, already
    built (its key is the files' names and everything but their rules); a text from a .dslr or a
    decision table gets a .drl name of its own."""
    return {(src.file if src.file.endswith(".drl") and not src.file.startswith("zz_") else f"zz_base_{n}.drl"):
            items.blanked(lambda item: item.kind != "rule")
            for n, (src, items) in enumerate(sources, start=1) if items is not None}


def build(engine: Any, files: dict[str, str]) -> Explainer:
    """Compile ``files`` (shared with their own build) and, apart, their declarations with every
    rule's diagnostic queries. A rule whose queries do not compile (a condition this reader does not
    understand) is left out of the queries and says so."""
    rules = engine.compile_draft(files)
    plans, sources = plan_rules(files)
    base = declarations(sources)
    skip: set[int] = set()
    for _attempt in range(4):
        extra = query_files(plans, sources, skip)
        _check_size(plans, {**base, **extra})
        try:
            return Explainer(plans, rules, engine.compile_draft({**base, **extra}))
        except CompileFailed as failed:
            ours = [e for e in failed.errors if e.file in extra]
            newly = _broken_rules(ours, extra, plans) - skip
            if not newly or len(ours) < len(failed.errors):
                raise
            for plan in plans:
                if plan.number in newly:
                    plan.broken = "its conditions could not be turned into diagnostic queries: " + ours[0].message
            skip |= newly
    raise EngineError("the diagnostic queries of this rule set do not compile")


class ExplainTooLarge(EngineError):
    """The rule set's diagnostic queries pass the bounds of a rule set's text (422): explained
    whole, they would be built as one more rule set that large, next to the live one."""

    kind = "invalid"


def _check_size(plans: list[RulePlan], files: dict[str, str]) -> None:
    """ExplainTooLarge when the queries' DRL passes MAX_TOTAL_BYTES or MAX_FILES. Why: at 10,000
    rules they are ~58,000 queries (~8 MB), which would need about as much heap again as the
    rules; the build's own upload check would say "rule set too large" of a set that is deployed."""
    size = sum(len(text.encode("utf-8")) for text in files.values())
    if size > MAX_TOTAL_BYTES or len(files) > MAX_FILES:
        queries = sum(text.count('\nquery "') + text.startswith('query "') for text in files.values())
        raise ExplainTooLarge(
            f"this rule set is too large to explain: its {len(plans):,} rules need {queries:,} diagnostic queries "
            f"({size / 1e6:.1f} MB of DRL; explain builds at most {MAX_TOTAL_BYTES / 1e6:.0f} MB in "
            f"{MAX_FILES} files: about 6,000 rules of simple shapes)")


class ExplainBusy(EngineError):
    """Too many explanations wait in this process (429)."""

    kind = "limit"


class ExplainCache:
    """Explainers by file content (a version, or a draft), built once, kept for the last few."""

    def __init__(self, size: int = CACHE_SIZE) -> None:
        self._size = size
        self._worker = priority.background_pool(1, "explain")
        self._waiting = threading.BoundedSemaphore(MAX_WAITING)
        self._built: OrderedDict[str, Explainer] = OrderedDict()
        self._lock = threading.Lock()
        self._building: dict[str, threading.Lock] = {}
        self._prebuild: OrderedDict[str, dict[str, str]] = OrderedDict()  # rule set -> its newest live files
        self._draining = False
        self.timings: deque[tuple[float, float]] = deque(maxlen=1000)  # (wall ms, CPU ms) of the last explanations
        self.builds = 0  # explainers built (a test asserts an explanation after a deploy builds none)

    def run(self, engine: Any, files: dict[str, str], facts: list[dict[str, Any]]) -> dict[str, Any]:
        """Explain ``facts`` on ``files``: built (once) and asked on the cache's own long-lived
        thread, one explanation at a time; more than MAX_WAITING waiting is refused (ExplainBusy).

        Why one thread: an explanation's first build compiles hundreds of queries; one at a time
        on a thread of its own, explaining never takes more than one core from serving, and the
        queue in front of it is bounded."""
        if not self._waiting.acquire(blocking=False):
            raise ExplainBusy(f"{MAX_WAITING} explanations are already waiting on this gateway process; try again shortly")
        try:
            return self._worker.submit(self._timed, engine, files, facts).result()
        finally:
            self._waiting.release()

    def _timed(self, engine: Any, files: dict[str, str], facts: list[dict[str, Any]]) -> dict[str, Any]:
        """One explanation on the explain thread, its wall and CPU time kept (``timings``): on a
        loaded machine the wall time says more about the neighbours than about explaining. The
        thread's CPU time includes the JVM's work, which runs on this same thread."""
        explainer = self.get(engine, files)
        wall, cpu = time.perf_counter(), time.thread_time()
        answer = explain(engine, explainer, facts)
        self.timings.append(((time.perf_counter() - wall) * 1000, (time.thread_time() - cpu) * 1000))
        return answer

    def has(self, files: dict[str, str]) -> bool:
        """Whether the explainer of ``files`` is built (an explanation of them compiles nothing)."""
        with self._lock:
            return content_hash(files) in self._built

    def prebuild(self, engine: Any, name: str, files: dict[str, str]) -> None:
        """Build the explainer of ``files`` (rule set ``name``'s new live version) soon, on the
        explain thread, off the serving path: the first explanation of a version then finds its
        queries compiled instead of compiling them (~10 s for the 32 reception rules).

        Bounded: one pending build per rule set (a newer deploy replaces an older one not started
        yet), at most CACHE_SIZE rule sets pending (the oldest dropped: it would leave the cache
        anyway); explanations asked meanwhile wait behind at most the build in progress."""
        with self._lock:
            if content_hash(files) in self._built:
                return
            self._prebuild.pop(name, None)
            self._prebuild[name] = files
            while len(self._prebuild) > self._size:
                self._prebuild.popitem(last=False)
            start, self._draining = not self._draining, True
        if start:
            try:
                self._worker.submit(self._drain, engine)
            except RuntimeError:  # the explain thread is shut down (closing): nothing to prepare for
                with self._lock:
                    self._draining = False

    def _drain(self, engine: Any) -> None:
        """On the explain thread: build the pending explainers, newest deploy of each rule set."""
        while True:
            with self._lock:
                if not self._prebuild:
                    self._draining = False
                    return
                name, files = self._prebuild.popitem(last=False)
            try:
                explainer = self.get(engine, files)
                # one explanation on the rule set's first example (or no facts) loads the queries'
                # classes and warms their code in the JVM: the first real one is then as quick as the next
                examples = warmup.example_fact_sets(files)
                explain(engine, explainer, examples[0] if examples else [])
            except Exception as exc:  # an explanation will build it again and report the error then
                log.warning("explain queries of %s not built in advance: %s", name, exc)

    def close(self) -> None:
        """Stop the explain thread (detached from the JVM first, as a thread that ends should be)
        and forget the built explainers. Builds waiting to be made in advance are dropped (only
        the one in progress is waited for)."""
        with self._lock:
            self._prebuild.clear()

        def detach() -> None:
            import jpype

            if jpype.isJVMStarted() and jpype.java.lang.Thread.isAttached():
                jpype.java.lang.Thread.detach()
        try:
            self._worker.submit(detach).result(timeout=30)
        except Exception:  # closing must go on
            log.debug("explain thread not detached", exc_info=True)
        self._worker.shutdown(wait=True)
        with self._lock:
            self._built.clear()

    def get(self, engine: Any, files: dict[str, str]) -> Explainer:
        key = content_hash(files)
        with self._lock:
            if key in self._built:
                self._built.move_to_end(key)
                return self._built[key]
            lock = self._building.setdefault(key, threading.Lock())
        with lock:  # one build per text, however many ask at once
            with self._lock:
                if key in self._built:
                    return self._built[key]
            explainer = build(engine, files)
            with self._lock:
                self.builds += 1
                self._built[key] = explainer
                while len(self._built) > self._size:
                    self._built.popitem(last=False)
                self._building.pop(key, None)
            return explainer


def explain(engine: Any, explainer: Explainer, facts: list[dict[str, Any]]) -> dict[str, Any]:
    """Fire ``facts`` on the rules in a throwaway session, then ask the diagnostic queries on the
    facts as the rules left them (another throwaway session) and explain every rule."""
    session = engine.explain_session(explainer.rules)
    try:
        session.insert(facts)
        result = session.fire(return_facts=True)
    finally:
        session.close()
    matches: dict[str, list[list[Any]]] = {}
    for entry in result.fired:
        matches.setdefault(entry["rule"], []).append(entry.get("facts") or [])
    queries = engine.explain_session(explainer.queries)
    try:
        queries.insert(result.facts)
        run = Run(queries)
        prefetch(run, [plan for plan in explainer.plans if plan.name not in matches and not plan.broken])
        groups = frozenset(plan.attributes["activation-group"] for plan in explainer.plans
                           if plan.name in matches and "activation-group" in plan.attributes)
        rules = [explain_rule(run, plan, matches.get(plan.name, []), groups) for plan in explainer.plans]
    finally:
        queries.close()
    return {"fired": [entry["rule"] for entry in result.fired], "actions": result.actions, "rules": rules}
