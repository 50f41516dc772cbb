"""The continuous query engine: registered C-SPARQL queries over timestamped RDF streams.

Window semantics (event time; deterministic on replay — no wall clock is ever read):

- A time window ``[RANGE r STEP s]`` closes at every multiple of ``s`` ms (epoch-aligned); the
  window closing at ``t`` holds the stream's triples with ``t - r <= timestamp < t``.
- A window is evaluated when the query's clock reaches its close: when a message with
  ``timestamp >= t`` arrives on any of the query's streams (or a heartbeat via :meth:`advance`).
  Windows that would hold no triple at all are skipped, not evaluated.
- Out-of-order messages are fine as long as their window is still open. A message older than the
  last closed window of a query (``timestamp < closed_until``) is *late*: dropped for that query and
  counted (``late_dropped``); results already emitted are never revised.
- ``[RANGE TRIPLES n]`` keeps the last ``n`` triples. A query with only count windows is evaluated
  after every message; mixed with time windows, at the time windows' closes.
- Memory is bounded: per query and stream at most ``max_window_triples`` triples are buffered; the
  oldest message is dropped beyond that and counted (``overflow_dropped``), with a warning.

Results (non-empty ones) go to subscribers — ``callback(event: dict)`` — and to a short history per
query; a query bound to a rule set turns rows into facts and fires the rules (see ``rules.py``).
"""

from __future__ import annotations

import bisect
import itertools
import logging
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable

from gateway.config import StreamSettings
from gateway.rdf.terms import Triple, term_to_json
from gateway.stream.evaluate import Evaluation, WindowData, check_sparql, evaluate_oxigraph
from gateway.stream.fastpath import Fallback, NotCompilable, Plan, compile_query, run_plan
from gateway.stream.lexer import QueryParseError, position
from gateway.stream.params import OntologySource, ParamError
from gateway.stream.query import ContinuousQuery, ParamSpec, WindowSpec, parse_query
from gateway.stream.rules import BindingError, RuleBinding, binding_facts, check_binding

log = logging.getLogger(__name__)

Subscriber = Callable[[dict[str, Any]], None]


class StreamError(ValueError):
    """A request the stream engine refuses (unknown query, too many queries, …)."""


class QueryNotFound(StreamError):
    pass


@dataclass
class _Buffer:
    """The timestamp-ordered messages of one stream kept for one query's window."""

    spec: WindowSpec
    stamps: list[int] = field(default_factory=list)
    items: list[list[Triple]] = field(default_factory=list)
    n_triples: int = 0

    def add(self, ts: int, triples: list[Triple]) -> None:
        if not self.stamps or ts >= self.stamps[-1]:
            self.stamps.append(ts)
            self.items.append(triples)
        else:
            i = bisect.bisect_right(self.stamps, ts)
            self.stamps.insert(i, ts)
            self.items.insert(i, triples)
        self.n_triples += len(triples)

    def drop_first(self, count: int) -> None:
        if count <= 0:
            return
        self.n_triples -= sum(len(x) for x in self.items[:count])
        del self.stamps[:count]
        del self.items[:count]

    def evict_before(self, ts: int) -> None:
        self.drop_first(bisect.bisect_left(self.stamps, ts))

    def keep_last_triples(self, n: int) -> None:
        drop, remaining = 0, self.n_triples
        while drop < len(self.items) - 1 and remaining - len(self.items[drop]) >= n:
            remaining -= len(self.items[drop])
            drop += 1
        self.drop_first(drop)

    def window(self, end: int, out: dict[Triple, int]) -> None:
        """Add this window's triples (ts < end) to ``out``, keeping each triple's latest timestamp."""
        stop = bisect.bisect_left(self.stamps, end)
        if self.spec.is_time:
            first = bisect.bisect_left(self.stamps, end - self.spec.range_ms)  # type: ignore[operator]
            for i in range(first, stop):
                ts = self.stamps[i]
                for t in self.items[i]:
                    if out.get(t, -1) <= ts:
                        out[t] = ts
            return
        remaining = self.spec.triples or 0
        picked: list[tuple[Triple, int]] = []
        for i in range(stop - 1, -1, -1):
            for t in reversed(self.items[i]):
                if remaining == 0:
                    break
                picked.append((t, self.stamps[i]))
                remaining -= 1
        for t, ts in picked:
            if out.get(t, -1) <= ts:
                out[t] = ts


@dataclass
class QueryRuntime:
    """A registered query and its evaluation state."""

    query: ContinuousQuery
    buffers: dict[str, _Buffer]
    results: deque[dict[str, Any]]
    next_close: int | None = None
    closed_until: int | None = None
    plan: Plan | None = None
    plan_text: str | None = None
    not_compilable: str | None = None
    binding: RuleBinding | None = None
    field_types: dict[str, dict[str, str]] = field(default_factory=dict)  # fact type -> field -> java type
    handled: dict[str, int] = field(default_factory=dict)  # suppress_repeats: key -> window end it fired
    session: Any = None
    param_values: dict[str, str] = field(default_factory=dict)
    param_error: str | None = None
    param_version: int = -1
    stats: dict[str, int] = field(default_factory=lambda: {
        "windows": 0, "fast": 0, "general": 0, "fallbacks": 0, "results": 0, "late_dropped": 0,
        "overflow_dropped": 0, "errors": 0, "rule_fires": 0, "rule_errors": 0, "skipped_windows": 0,
    })
    eval_ms: deque[float] = field(default_factory=lambda: deque(maxlen=512))
    last_error: str | None = None

    def info(self) -> dict[str, Any]:
        q = self.query
        ms = sorted(self.eval_ms)
        return {
            "name": q.name,
            "kind": q.kind,
            "form": q.form,
            "text": q.text,
            "windows": [w.to_dict() for w in q.windows],
            "static_graphs": q.static_graphs,
            "params": [p.to_dict() for p in q.params],
            "param_values": dict(self.param_values),
            "param_error": self.param_error,
            "fast_path": self.plan is not None,
            "not_compilable": self.not_compilable,
            "binding": self.binding.to_dict() if self.binding else None,
            "closed_until": self.closed_until,
            "stats": dict(self.stats),
            "eval_ms_p50": ms[len(ms) // 2] if ms else None,
            "eval_ms_p99": ms[min(len(ms) - 1, int(len(ms) * 0.99))] if ms else None,
            "last_error": self.last_error,
            "buffered_triples": {s: b.n_triples for s, b in self.buffers.items()},
        }


class StreamEngine:
    """Registers queries, takes timestamped triples, evaluates windows and publishes results."""

    def __init__(self, settings: StreamSettings | None = None, rules_engine: Any = None,
                 ontology: OntologySource | None = None,
                 providers: dict[str, Callable[[], list[dict[str, Any]]]] | None = None) -> None:
        self.settings = settings or StreamSettings()
        self.rules_engine = rules_engine
        self.providers = dict(providers or {})  # context facts a binding can ask for (e.g. "robots")
        self.ontology = ontology if ontology is not None else OntologySource(self.settings.ontology_file)
        self._queries: dict[str, QueryRuntime] = {}
        self._static: dict[str, frozenset[Triple]] = {}
        self._subscribers: dict[int, tuple[Subscriber, str | None]] = {}
        self._ids = itertools.count(1)
        self._lock = threading.RLock()
        self.stream_stats: dict[str, dict[str, int]] = {}
        self.subscriber_errors = 0

    # -- static graphs -----------------------------------------------------------------------------
    def add_static_graph(self, iri: str, triples: set[Triple] | frozenset[Triple]) -> None:
        """Make ``triples`` available as ``FROM <iri>`` / ``FROM NAMED <iri>`` to queries."""
        with self._lock:
            self._static[iri] = frozenset(triples)

    def share_static_graphs(self, other: "StreamEngine") -> None:
        """Use ``other``'s static graphs (a scratch engine that checks queries for it)."""
        self._static = other._static

    def _graph(self, iri: str) -> frozenset[Triple]:
        if iri == self.settings.ontology_graph:
            return self.ontology.triples
        return self._static[iri]

    def _known_graphs(self) -> list[str]:
        return sorted(set(self._static) | {self.settings.ontology_graph})

    # -- queries -----------------------------------------------------------------------------------
    def register(self, text: str, params: list[ParamSpec] | None = None, replace: bool = False,
                 binding: RuleBinding | None = None) -> dict[str, Any]:
        """Parse, check and register a C-SPARQL query; raises QueryParseError / StreamError."""
        query = parse_query(text, params)
        try:
            check_sparql(query.sparql)
        except SyntaxError as exc:
            raise _positioned(str(exc)) from None
        for iri in query.static_graphs + query.named_graphs:
            if iri not in self._known_graphs():
                line, col = position(text, text.find(iri)) if iri in text else (0, 0)
                raise QueryParseError(f"unknown static graph <{iri}>; known: {self._known_graphs()}", line, col)
        with self._lock:
            if query.name in self._queries and not replace:
                raise StreamError(f"a query named {query.name!r} is already registered")
            if query.name not in self._queries and len(self._queries) >= self.settings.max_queries:
                raise StreamError(f"at most {self.settings.max_queries} queries may be registered")
            runtime = QueryRuntime(
                query=query,
                buffers={w.stream: _Buffer(w) for w in query.windows},
                results=deque(maxlen=self.settings.results_kept),
            )
            self._bind_params(runtime)
            if binding is not None:
                self._check_binding(runtime, binding)
            old = self._queries.get(query.name)
            if old is not None and old.session is not None:
                self._close_session(old.session)
            self._queries[query.name] = runtime
            return runtime.info()

    def bind_rules(self, name: str, binding: RuleBinding | None) -> dict[str, Any]:
        """Bind (or with None, unbind) a query's results to a rule set."""
        with self._lock:
            runtime = self._get(name)
            if runtime.session is not None:
                self._close_session(runtime.session)
                runtime.session = None
            runtime.binding = None
            if binding is not None:
                self._check_binding(runtime, binding)
            return runtime.info()

    def _check_binding(self, runtime: QueryRuntime, binding: RuleBinding) -> None:
        if self.rules_engine is None:
            raise BindingError("no rules engine is configured")
        if runtime.query.form != "SELECT":
            raise BindingError("only SELECT queries can feed rules")
        variables = _select_variables(runtime.query)
        runtime.field_types = check_binding(binding, variables, self.rules_engine, self.providers)
        runtime.handled = {}
        runtime.binding = binding

    def unregister(self, name: str) -> None:
        with self._lock:
            runtime = self._queries.pop(name, None)
            if runtime is None:
                raise QueryNotFound(f"no query named {name!r}")
            if runtime.session is not None:
                self._close_session(runtime.session)

    def queries(self) -> list[dict[str, Any]]:
        with self._lock:
            return [r.info() for r in self._queries.values()]

    def query_info(self, name: str) -> dict[str, Any]:
        with self._lock:
            return self._get(name).info()

    def results(self, name: str, limit: int = 20) -> list[dict[str, Any]]:
        with self._lock:
            return list(self._get(name).results)[-limit:]

    def _get(self, name: str) -> QueryRuntime:
        runtime = self._queries.get(name)
        if runtime is None:
            raise QueryNotFound(f"no query named {name!r}")
        return runtime

    # -- subscribers -------------------------------------------------------------------------------
    def subscribe(self, callback: Subscriber, query: str | None = None) -> int:
        """``callback(event)`` for every result/actions/error event (of one query, or all)."""
        with self._lock:
            token = next(self._ids)
            self._subscribers[token] = (callback, query)
            return token

    def unsubscribe(self, token: int) -> None:
        with self._lock:
            self._subscribers.pop(token, None)

    def _publish(self, event: dict[str, Any]) -> None:
        for callback, query in list(self._subscribers.values()):
            if query is not None and query != event.get("query"):
                continue
            try:
                callback(event)
            except Exception:  # a subscriber must never stop the stream
                self.subscriber_errors += 1
                log.exception("stream subscriber failed on a %s event", event.get("kind"))

    # -- input -------------------------------------------------------------------------------------
    def push(self, stream: str, timestamp_ms: int, triples: list[Triple]) -> dict[str, Any]:
        """Add one timestamped message to ``stream``; evaluates every window it closes.

        Returns what happened: windows evaluated, and for which queries the message was late or
        did not fit (never silent).
        """
        ts = int(timestamp_ms)
        if len(triples) > self.settings.max_message_triples:
            raise StreamError(f"a message may hold at most {self.settings.max_message_triples} triples")
        report: dict[str, Any] = {"stream": stream, "timestamp": ts, "triples": len(triples),
                                  "queries": 0, "evaluated": 0, "late_for": [], "overflow_for": []}
        with self._lock:
            stats = self.stream_stats.setdefault(stream, {"messages": 0, "triples": 0})
            stats["messages"] += 1
            stats["triples"] += len(triples)
            for runtime in list(self._queries.values()):
                buffer = runtime.buffers.get(stream)
                if buffer is None:
                    continue
                report["queries"] += 1
                if runtime.closed_until is not None and ts < runtime.closed_until:
                    runtime.stats["late_dropped"] += 1
                    report["late_for"].append(runtime.query.name)
                    continue
                report["evaluated"] += self._advance(runtime, ts)
                if triples:
                    buffer.add(ts, list(triples))
                    if self._enforce_bound(runtime, buffer):
                        report["overflow_for"].append(runtime.query.name)
                if runtime.query.step_ms is None and triples:
                    report["evaluated"] += self._evaluate(runtime, ts + 1)
        return report

    def advance(self, timestamp_ms: int, stream: str | None = None) -> int:
        """Move the clock of the queries (on ``stream``, or all) to ``timestamp_ms`` (a heartbeat)."""
        with self._lock:
            return sum(self._advance(r, int(timestamp_ms)) for r in list(self._queries.values())
                       if stream is None or stream in r.buffers)

    def _enforce_bound(self, runtime: QueryRuntime, buffer: _Buffer) -> bool:
        limit = self.settings.max_window_triples
        dropped = 0
        while buffer.n_triples > limit and len(buffer.items) > 1:
            buffer.drop_first(1)
            dropped += 1
        if dropped:
            if runtime.stats["overflow_dropped"] == 0:
                log.warning("query %s: more than %d triples buffered; dropping the oldest messages",
                            runtime.query.name, limit)
            runtime.stats["overflow_dropped"] += dropped
        return dropped > 0

    def _advance(self, runtime: QueryRuntime, ts: int) -> int:
        """Evaluate every window of ``runtime`` that closes at or before ``ts``."""
        step = runtime.query.step_ms
        if step is None:
            return 0
        if runtime.next_close is None:
            runtime.next_close = (ts // step + 1) * step
            return 0
        evaluated = 0
        max_range = max(w.range_ms or 0 for w in runtime.query.windows)
        while runtime.next_close <= ts:
            end = runtime.next_close
            for b in runtime.buffers.values():
                if b.spec.is_time:
                    b.evict_before(end - b.spec.range_ms)  # type: ignore[operator]
            if all(not b.stamps or b.stamps[0] >= end for b in runtime.buffers.values()):
                # nothing in this window: jump to the last close <= ts without evaluating
                last = (ts // step) * step
                runtime.stats["skipped_windows"] += (last - end) // step + 1
                runtime.closed_until = last
                runtime.next_close = last + step
                break
            evaluated += self._evaluate(runtime, end)
            runtime.closed_until = end
            runtime.next_close = end + step
        for b in runtime.buffers.values():
            if b.spec.is_time:
                b.evict_before(runtime.next_close - max_range)
            else:
                b.keep_last_triples(b.spec.triples or 0)
        return evaluated

    # -- evaluation --------------------------------------------------------------------------------
    def _bind_params(self, runtime: QueryRuntime) -> bool:
        """(Re)bind parameters; recompile the fast path when a value changed. False if unbound."""
        if runtime.plan_text is not None and runtime.param_version == self.ontology.version \
                and runtime.param_error is None:
            return True  # the ontology did not change since the last binding
        values: dict[str, str] = {}
        try:
            for spec in runtime.query.params:
                values[spec.name] = self.ontology.bind(spec)
        except ParamError as exc:
            runtime.param_error = str(exc)
            return bool(runtime.param_values) or not runtime.query.params
        runtime.param_error = None
        runtime.param_version = self.ontology.version
        if values != runtime.param_values or runtime.plan_text is None:
            runtime.param_values = values
            text = runtime.query.executable(values)
            runtime.plan_text = text
            runtime.plan, runtime.not_compilable = None, None
            if self.settings.fast_path:
                try:
                    runtime.plan = compile_query(text)
                except NotCompilable as exc:
                    runtime.not_compilable = str(exc)
        return True

    def window_data(self, runtime: QueryRuntime, end: int) -> WindowData:
        step = runtime.query.step_ms
        max_range = max((w.range_ms or 0 for w in runtime.query.windows), default=0)
        data = WindowData(start_ms=end - max_range if step else end, end_ms=end)
        for buffer in runtime.buffers.values():
            buffer.window(end, data.stamped)
        static: set[Triple] = set()
        for iri in runtime.query.static_graphs:
            static |= self._graph(iri)
        data.static = frozenset(static)
        data.named = {iri: self._graph(iri) for iri in runtime.query.named_graphs}
        return data

    def _evaluate(self, runtime: QueryRuntime, end: int) -> int:
        self.ontology.refresh()
        if not self._bind_params(runtime):
            runtime.stats["errors"] += 1
            runtime.last_error = runtime.param_error
            self._publish({"kind": "error", "query": runtime.query.name, "error": runtime.param_error})
            return 0
        data = self.window_data(runtime, end)
        started = time.perf_counter()
        try:
            evaluation = self._run(runtime, data)
        except Exception as exc:
            runtime.stats["errors"] += 1
            runtime.last_error = f"window ending {end}: {exc}"
            log.warning("query %s failed on the window ending at %d: %s", runtime.query.name, end, exc)
            self._publish({"kind": "error", "query": runtime.query.name, "error": runtime.last_error})
            return 1
        elapsed = (time.perf_counter() - started) * 1000
        runtime.eval_ms.append(elapsed)
        runtime.stats["windows"] += 1
        runtime.stats["fast" if evaluation.path == "fast" else "general"] += 1
        if evaluation.rows:
            event = _result_event(runtime.query.name, data, evaluation, elapsed)
            runtime.stats["results"] += 1
            runtime.results.append(event)
            self._publish(event)
            if runtime.binding is not None:
                self._feed_rules(runtime, evaluation, data)
        return 1

    def _run(self, runtime: QueryRuntime, data: WindowData) -> Evaluation:
        if runtime.plan is not None:
            try:
                return run_plan(runtime.plan, data)
            except Fallback:
                runtime.stats["fallbacks"] += 1
        return evaluate_oxigraph(runtime.plan_text or runtime.query.sparql, data)

    def _feed_rules(self, runtime: QueryRuntime, evaluation: Evaluation, data: WindowData) -> None:
        binding = runtime.binding
        assert binding is not None
        name = runtime.query.name
        try:
            facts = binding_facts(binding, evaluation.rows, runtime.field_types, data, self.providers, runtime.handled)
            if not facts:
                return  # every row was a repeat: nothing new to decide
            window = {"start": data.start_ms, "end": data.end_ms}
            correlation = f"{name}@{data.end_ms}"
            if binding.mode == "stateful":
                if runtime.session is None:
                    runtime.session = self.rules_engine.open_session(binding.ruleset)
                # insert stamped with the window's end (the clock moves there first) and fire: one JVM call
                result = runtime.session.push(facts, data.end_ms)
                result.decision_id = self.rules_engine.record_decision(
                    result, facts, origin="stream", correlation_id=correlation, context={"query": name, "window": window})
            else:
                result = self.rules_engine.fire(binding.ruleset, facts, origin="stream", correlation_id=correlation,
                                                context={"query": name, "window": window})
        except Exception as exc:
            runtime.stats["rule_errors"] += 1
            runtime.last_error = f"rules {binding.ruleset!r}: {exc}"
            log.warning("query %s: firing %s failed: %s", name, binding.ruleset, exc)
            self._publish({"kind": "error", "query": name, "error": runtime.last_error})
            return
        runtime.stats["rule_fires"] += 1
        payload = result.to_dict() if hasattr(result, "to_dict") else dict(result)
        self._publish({
            "kind": "actions", "query": name, "ruleset": binding.ruleset, "version": payload.get("version"),
            "decision_id": payload.get("decision_id"), "window": window, "facts": facts,
            "actions": payload.get("actions", []), "fired": payload.get("fired", []), "dispatch": binding.dispatch,
        })

    def _close_session(self, session: Any) -> None:
        closer = getattr(self.rules_engine, "close_session", None)
        try:
            closer(session.id) if closer is not None and hasattr(session, "id") else session.close()
        except Exception:  # closing a dead session must not hide the real work
            log.debug("closing a rules session failed", exc_info=True)

    def close(self) -> None:
        with self._lock:
            for runtime in self._queries.values():
                if runtime.session is not None:
                    self._close_session(runtime.session)
                    runtime.session = None


def _result_event(name: str, data: WindowData, evaluation: Evaluation, elapsed_ms: float) -> dict[str, Any]:
    return {
        "kind": "result",
        "query": name,
        "window": {"start": data.start_ms, "end": data.end_ms, "triples": data.size},
        "variables": evaluation.variables,
        "rows": [{k: term_to_json(v) for k, v in row.items()} for row in evaluation.rows],
        "path": evaluation.path,
        "eval_ms": round(elapsed_ms, 3),
    }


def _select_variables(query: ContinuousQuery) -> list[str]:
    """The projected variables (from the SPARQL engine's view of the query)."""
    return evaluate_oxigraph(query.executable({p.name: '""' for p in query.params}), WindowData(0, 0)).variables


def _positioned(message: str) -> QueryParseError:
    """pyoxigraph's "error at L:C: …" as a QueryParseError with line and column."""
    import re

    match = re.match(r"error at (\d+):(\d+): (.*)", message, re.S)
    if match:
        return QueryParseError(match.group(3).strip(), int(match.group(1)), int(match.group(2)))
    return QueryParseError(message, 0, 0)
