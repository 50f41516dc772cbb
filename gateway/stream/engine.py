"""The continuous query engine: registered C-SPARQL / RSP-QL queries over timestamped RDF streams.

Semantics (event time; deterministic on replay — no wall clock is ever read; docs/streams.md has
the full text):

- A time window ``[RANGE r STEP s]`` closes at every multiple of ``s`` ms (epoch-aligned); the
  window closing at ``c`` holds the triples with ``c - r <= timestamp < c``. ``[RANGE TRIPLES n]``
  holds the last ``n`` triples. The query's clock is the latest timestamp seen on any of its
  streams (or given by a heartbeat, :meth:`StreamEngine.advance`).
- Every window is evaluated, empty or not, according to the query's report policy (on window
  close — the default —, on content change, periodic; optionally only non-empty content). A long
  gap stays cheap: a run of empty windows is evaluated once and at most ``max_catchup_windows``
  of them are reported (the rest counted as ``skipped_windows``, the last one says how many).
- Late data (older than the end of the last closed window) is dropped and counted; results
  already reported are never revised, and no window ever sees a late triple.
- Every reported window is kept (the last ``results_kept``) and published to subscribers as a
  :class:`~gateway.stream.results.ResultEvent`: plain JSON rows plus the RDF terms.
- ``REGISTER STREAM s AS CONSTRUCT …`` feeds its triples, stamped with the evaluation instant, to
  the stream ``s`` (other queries read it ``FROM STREAM <s>``; rules can be bound to it). Cycles
  are refused at registration.
"""

from __future__ import annotations

import itertools
import logging
import re
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pyoxigraph import Literal, NamedNode

from gateway.config import StreamSettings
from gateway.rdf.terms import DEFAULT_PREFIXES, XSD, Term, Triple, canonical_term, canonical_triple, parse_node
from gateway.stream.analysis import construct_fields, relevant_predicates
from gateway.stream.evaluate import (
    Evaluation,
    WindowData,
    check_sparql,
    evaluate_oxigraph,
)
from gateway.stream.fastpath import (
    Fallback,
    NotCompilable,
    Plan,
    compile_query,
    run_plan,
)
from gateway.stream.lexer import QueryParseError, position
from gateway.stream.params import OntologySource, ParamError
from gateway.stream.query import (
    ContinuousQuery,
    ParamSpec,
    ReportPolicy,
    WindowSpec,
    duration_ms,
    parse_query,
)
from gateway.stream.results import (
    ResultEvent,
    Row,
    plain_rows,
    rows_to_triples,
    sort_rows,
    stream_diff,
    to_sparql_json,
    triples_as_facts,
)
from gateway.stream.binding_fire import BindingFirer, Job
from gateway.stream.rules import BindingError, RuleBinding, binding_facts, check_binding
from gateway.stream.windows import StreamBuffer, merge, merge_latest, pane_size

log = logging.getLogger(__name__)

Subscriber = Callable[[dict[str, Any]], None]
InputListener = Callable[[str, int, list[Triple]], None]


class StreamError(ValueError):
    """A request the stream engine refuses (unknown query, too many queries, …)."""


class QueryNotFound(StreamError):
    pass


def _new_stats() -> dict[str, int]:
    return {
        "windows": 0, "reported": 0, "empty_windows": 0, "skipped_windows": 0, "fast": 0, "general": 0,
        "fallbacks": 0, "results": 0, "late_dropped": 0, "overflow_dropped": 0, "errors": 0, "rule_fires": 0,
        "rule_errors": 0, "derived_triples": 0, "rule_skipped": 0, "rule_late": 0,
    }


@dataclass
class QueryRuntime:
    """A registered query and its evaluation state."""

    query: ContinuousQuery
    buffers: dict[str, StreamBuffer]
    results: deque[ResultEvent]
    nonempty: deque[ResultEvent]
    windows: list[WindowSpec] = field(default_factory=list)  # with parameter ranges bound
    relevant: frozenset[NamedNode] | None = None
    next_close: int | None = None
    next_periodic: int | None = None
    closed_until: int | None = None
    clock: int | None = None
    plan: Plan | None = None
    plan_text: str | None = None
    not_compilable: str | None = None
    binding: RuleBinding | None = None
    field_types: dict[str, dict[str, str]] = field(default_factory=dict)  # fact type -> field -> java type
    handled: dict[str, int] = field(default_factory=dict)  # suppress_repeats: key -> window end it fired
    session: Any = None
    firer: BindingFirer | None = None  # the binding's thread (gateway.stream.binding_fire)
    param_values: dict[str, str] = field(default_factory=dict)
    param_error: str | None = None
    param_version: int = -1
    last_rows: list[Row] | None = None
    cc_dirty: bool = False
    cc_starts: tuple[int | None, ...] | None = None  # per window: the oldest timestamp last reported
    empty_cache: tuple[Any, Evaluation] | None = None
    static_cache: tuple[Any, frozenset[Triple]] | None = None
    seq: int = 0
    stats: dict[str, int] = field(default_factory=_new_stats)
    eval_ms: deque[float] = field(default_factory=lambda: deque(maxlen=512))
    last_error: str | None = None

    @property
    def step(self) -> int | None:
        return self.query.step_ms

    def max_range(self) -> int:
        return max((w.range_ms or 0 for w in self.windows if w.is_time), default=0)

    def info(self) -> dict[str, Any]:
        q = self.query
        ms = sorted(self.eval_ms)
        return {
            "name": q.name,
            "kind": q.kind,
            "form": q.form,
            "text": q.text,
            "windows": [w.to_dict() for w in self.windows],
            "report": q.report.to_dict(),
            "operator": q.r2s,
            "output_stream": q.output_stream,
            "input_streams": q.streams,
            "static_graphs": q.static_graphs,
            "params": [p.to_dict() for p in q.params],
            "param_values": dict(self.param_values),
            "param_error": self.param_error,
            "fast_path": self.plan is not None,
            "not_compilable": self.not_compilable,
            "binding": self.binding.to_dict() if self.binding else None,
            "relevant_predicates": sorted(p.value for p in self.relevant) if self.relevant is not None else None,
            "clock": self.clock,
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
        self._order: list[QueryRuntime] = []  # producers of derived streams before their consumers
        self._static: dict[str, frozenset[Triple]] = {}
        self._static_version = 0
        self._ontology_canonical: tuple[int, frozenset[Triple]] | None = None
        self._subscribers: dict[int, tuple[Subscriber, str | None, bool]] = {}
        self._input_listeners: list[InputListener] = []
        self._ids = itertools.count(1)
        self._lock = threading.RLock()
        self.stream_stats: dict[str, dict[str, int]] = {}
        self.subscriber_errors = 0
        # a replay's scratch engine fires its bindings on the pushing thread, in window order:
        # no binding thread, no skipped or late window (see gateway.stream.replay)
        self.inline_fires = False

    # -- static graphs -----------------------------------------------------------------------------
    def add_static_graph(self, iri: str, triples: set[Triple] | frozenset[Triple]) -> None:
        """Make ``triples`` available as ``FROM <iri>`` / ``FROM NAMED <iri>`` to queries."""
        with self._lock:
            self._static[iri] = frozenset(canonical_triple(t) for t in triples)
            self._static_version += 1

    def share_static_graphs(self, other: "StreamEngine") -> None:
        """Use ``other``'s static graphs (a scratch engine that checks queries for it)."""
        self._static = other._static

    def _graph(self, iri: str) -> frozenset[Triple]:
        if iri == self.settings.ontology_graph:
            triples = self.ontology.triples
            version = self.ontology.version
            if self._ontology_canonical is None or self._ontology_canonical[0] != version:
                self._ontology_canonical = (version, frozenset(canonical_triple(t) for t in triples))
            return self._ontology_canonical[1]
        return self._static[iri]

    def _known_graphs(self) -> list[str]:
        return sorted(set(self._static) | {self.settings.ontology_graph})

    # -- queries -----------------------------------------------------------------------------------
    def register(self, text: str, params: list[ParamSpec] | None = None, replace: bool = False,
                 binding: RuleBinding | None = None, report: ReportPolicy | str | None = None) -> dict[str, Any]:
        """Parse, check and register a continuous query; raises QueryParseError / StreamError.

        ``report`` (a :class:`ReportPolicy` or its text, e.g. ``"content change"``) overrides the
        query's REPORT clause."""
        if isinstance(report, str):
            report = ReportPolicy.parse(report)
        query = parse_query(text, params, report)
        try:
            check_sparql(query.sparql)
        except SyntaxError as exc:
            raise _positioned(str(exc)) from None
        for iri in query.static_graphs + query.named_graphs:
            if iri not in self._known_graphs():
                line, col = position(text, text.find(iri)) if iri in text else (0, 0)
                raise QueryParseError(f"unknown static graph <{iri}>; known: {self._known_graphs()}", line, col)
        for w in query.windows:
            if w.name is not None and w.name in query.named_graphs:
                raise QueryParseError(f"<{w.name}> is both a named window and a FROM NAMED graph", w.line, w.column)
        with self._lock:
            if query.name in self._queries and not replace:
                raise StreamError(f"a query named {query.name!r} is already registered")
            if query.name not in self._queries and len(self._queries) >= self.settings.max_queries:
                raise StreamError(f"at most {self.settings.max_queries} queries may be registered")
            self._check_cycles(query)
            runtime = QueryRuntime(
                query=query,
                buffers={s: StreamBuffer(s) for s in query.streams},
                results=deque(maxlen=self.settings.results_kept),
                nonempty=deque(maxlen=self.settings.results_kept),
                windows=list(query.windows),
                relevant=relevant_predicates(query.sparql),
            )
            self._bind_params(runtime)
            if binding is not None:
                self._check_binding(runtime, binding)
            old = self._queries.get(query.name)
            if old is not None:
                self._stop_binding(old)
            self._queries[query.name] = runtime
            self._reorder()
            return runtime.info()

    def _check_cycles(self, query: ContinuousQuery) -> None:
        """Refuse a query whose output would, through other queries, reach its own inputs."""
        producers = {q.query.output_stream: q.query for q in self._queries.values()
                     if q.query.output_stream and q.query.name != query.name}
        if query.output_stream:
            producers[query.output_stream] = query

        def path_to(stream: str, target: str, seen: set[str]) -> list[str] | None:
            """The chain of streams from ``stream`` back to the producer of ``target``."""
            producer = producers.get(stream)
            if producer is None or stream in seen:
                return None
            if producer.name == target:
                return [stream]
            seen.add(stream)
            for upstream in producer.streams:
                chain = path_to(upstream, target, seen)
                if chain is not None:
                    return [stream] + chain
            return None

        if not query.output_stream:
            return
        for w in query.windows:
            chain = path_to(w.stream, query.name, set())
            if chain is not None:
                names = " → ".join(f"<{s}>" for s in list(reversed(chain)) + [query.output_stream])
                raise QueryParseError(f"stream cycle: {names} (query {query.name!r} would read its own output)",
                                      w.line, w.column)

    def _reorder(self) -> None:
        """Producers first: a derived stream's triples reach its readers before the readers move on."""
        runtimes = list(self._queries.values())
        by_output = {r.query.output_stream: r for r in runtimes if r.query.output_stream}
        order: list[QueryRuntime] = []
        placed: set[str] = set()

        def place(r: QueryRuntime) -> None:
            if r.query.name in placed:
                return
            placed.add(r.query.name)
            for s in r.query.streams:
                producer = by_output.get(s)
                if producer is not None and producer is not r:
                    place(producer)
            order.append(r)

        for r in runtimes:
            place(r)
        self._order = order

    def bind_rules(self, name: str, binding: RuleBinding | None) -> dict[str, Any]:
        """Bind (or with None, unbind) a query's (or a stream's) results to a rule set."""
        with self._lock:
            runtime = self._get(name)
            self._stop_binding(runtime)
            runtime.binding = None
            runtime.relevant = relevant_predicates(runtime.query.sparql)
            if binding is not None:
                self._check_binding(runtime, binding)
            return runtime.info()

    def _check_binding(self, runtime: QueryRuntime, binding: RuleBinding) -> None:
        if self.rules_engine is None:
            raise BindingError("no rules engine is configured")
        if runtime.query.form == "SELECT":
            variables = _select_variables(runtime.query)
        elif runtime.query.form == "CONSTRUCT":
            variables = construct_fields(runtime.query.sparql)
        else:
            raise BindingError(f"only SELECT queries and CONSTRUCT streams can feed rules, not {runtime.query.form}")
        runtime.field_types = check_binding(binding, variables, self.rules_engine, self.providers)
        runtime.handled = {}
        runtime.binding = binding
        runtime.relevant = _with_attributes(relevant_predicates(runtime.query.sparql), binding)

    def unregister(self, name: str) -> None:
        with self._lock:
            runtime = self._queries.pop(name, None)
            if runtime is None:
                raise QueryNotFound(f"no query named {name!r}")
            self._stop_binding(runtime)
            self._reorder()

    def queries(self) -> list[dict[str, Any]]:
        with self._lock:
            return [r.info() for r in self._queries.values()]

    def query_info(self, name: str) -> dict[str, Any]:
        with self._lock:
            return self._get(name).info()

    def results(self, name: str, limit: int = 20, nonempty: bool = False) -> list[dict[str, Any]]:
        """The last ``limit`` reported windows of a query, oldest first (empty ones included unless
        ``nonempty``: then the last windows that had at least one solution)."""
        with self._lock:
            runtime = self._get(name)
            kept = runtime.nonempty if nonempty else runtime.results
            return list(kept)[-limit:] if limit > 0 else []

    @staticmethod
    def sparql_json(event: dict[str, Any]) -> dict[str, Any]:
        """An event in the SPARQL 1.1 Query Results JSON format (see ``results.to_sparql_json``)."""
        return to_sparql_json(event)

    def _get(self, name: str) -> QueryRuntime:
        runtime = self._queries.get(name)
        if runtime is None:
            raise QueryNotFound(f"no query named {name!r}")
        return runtime

    # -- subscribers -------------------------------------------------------------------------------
    def subscribe(self, callback: Subscriber, query: str | None = None, nonempty: bool = False) -> int:
        """``callback(event)`` for every result/actions/error event (of one query, or all);
        ``nonempty``: result events only for windows with at least one solution."""
        with self._lock:
            token = next(self._ids)
            self._subscribers[token] = (callback, query, nonempty)
            return token

    def unsubscribe(self, token: int) -> None:
        with self._lock:
            self._subscribers.pop(token, None)

    def add_input_listener(self, listener: InputListener) -> None:
        """``listener(stream, timestamp_ms, triples)`` for every message pushed from outside (sensor
        readings as they arrive, before the windows they close are evaluated: the live view shows a
        reading before what was detected in it). Errors are logged, never raised."""
        with self._lock:
            self._input_listeners.append(listener)

    def _publish(self, event: dict[str, Any]) -> None:
        solutions = event.get("solutions", 1)
        for callback, query, nonempty in list(self._subscribers.values()):
            if query is not None and query != event.get("query"):
                continue
            if nonempty and event.get("kind") == "result" and not solutions:
                continue
            try:
                callback(event)
            except Exception:  # a subscriber must never stop the stream
                self.subscriber_errors += 1
                log.exception("stream subscriber failed on a %s event", event.get("kind"))

    # -- input -------------------------------------------------------------------------------------
    def push(self, stream: str, timestamp_ms: int, triples: list[Triple],
             with_results: bool = False) -> dict[str, Any]:
        """Add one timestamped message to ``stream``; evaluates every window it closes.

        Returns what happened: windows evaluated and reported, and for which queries the message
        was late or did not fit (never silent). ``with_results``: the report also holds the result
        events this message caused (``results``; see ``results.report_to_sparql_json``)."""
        ts = int(timestamp_ms)
        if len(triples) > self.settings.max_message_triples:
            raise StreamError(f"a message may hold at most {self.settings.max_message_triples} triples")
        report: dict[str, Any] = {"stream": stream, "timestamp": ts, "triples": len(triples),
                                  "queries": 0, "evaluated": 0, "reported": 0, "late_for": [],
                                  "overflow_for": [], "derived": 0}
        collected: list[ResultEvent] | None = [] if with_results else None
        canonical = [canonical_triple(t) if type(t[2]) is Literal else t for t in triples]
        with self._lock:
            for listener in self._input_listeners:
                try:
                    listener(stream, ts, canonical)
                except Exception:  # an observer must never stop the stream
                    self.subscriber_errors += 1
                    log.exception("stream input listener failed")
            self._ingest(stream, ts, canonical, report, collected, external=True)
        if collected is not None:
            report["results"] = collected
        return report

    def advance(self, timestamp_ms: int, stream: str | None = None) -> int:
        """Move the clock of the queries (reading ``stream``, or all) to ``timestamp_ms`` (a heartbeat);
        returns the number of windows evaluated."""
        ts = int(timestamp_ms)
        report: dict[str, Any] = {"evaluated": 0, "reported": 0, "derived": 0}
        with self._lock:
            for runtime in list(self._order):
                if stream is not None and stream not in runtime.buffers:
                    continue
                if runtime.closed_until is not None and ts < runtime.closed_until:
                    continue
                self._advance(runtime, ts, report, None)
                if runtime.query.report.trigger == "content_change":
                    self._tick(runtime, ts, report, None)
        return report["evaluated"]

    def _ingest(self, stream: str, ts: int, triples: list[Triple], report: dict[str, Any],
                collected: list[ResultEvent] | None, external: bool = False) -> None:
        if triples or external:
            stats = self.stream_stats.setdefault(stream, {"messages": 0, "triples": 0})
            stats["messages"] += 1
            stats["triples"] += len(triples)
        for runtime in list(self._order):
            buffer = runtime.buffers.get(stream)
            if buffer is None or runtime.query.name not in self._queries:
                continue
            if external:
                report["queries"] += 1
            if runtime.closed_until is not None and ts < runtime.closed_until:
                runtime.stats["late_dropped"] += 1
                if "late_for" in report:
                    report["late_for"].append(runtime.query.name)
                continue
            self._advance(runtime, ts, report, collected)
            kept = triples if runtime.relevant is None else [t for t in triples if t[1] in runtime.relevant]
            if kept:
                buffer.add(ts, kept)
                runtime.cc_dirty = True
                if self._enforce_bound(runtime, buffer) and "overflow_for" in report:
                    report["overflow_for"].append(runtime.query.name)
            if runtime.step is None:  # only count windows: every message is an evaluation instant
                runtime.clock = ts if runtime.clock is None else max(runtime.clock, ts)
                if kept:
                    self._instant(runtime, ts + 1, ts + 1, report, collected)
                runtime.closed_until = ts
                self._evict(runtime)
            elif runtime.query.report.trigger == "content_change":
                self._tick(runtime, ts + 1, report, collected)

    def _enforce_bound(self, runtime: QueryRuntime, buffer: StreamBuffer) -> bool:
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

    # -- the clock -----------------------------------------------------------------------------------
    def _advance(self, runtime: QueryRuntime, ts: int, report: dict[str, Any],
                 collected: list[ResultEvent] | None) -> None:
        """Process every evaluation instant of ``runtime`` up to ``ts``: window closes (and reports
        under ON WINDOW CLOSE), periodic reports; bounded catch-up over empty stretches."""
        runtime.clock = ts if runtime.clock is None else max(runtime.clock, ts)
        step = runtime.step
        if step is None:
            return
        policy = runtime.query.report
        period = policy.period_ms if policy.trigger == "periodic" else None
        if runtime.next_close is None:
            runtime.next_close = (ts // step + 1) * step
            if period:
                runtime.next_periodic = (ts // period + 1) * period
            return
        while True:
            close = runtime.next_close
            if policy.trigger == "window_close":
                report_at: int | None = close
            elif period:
                report_at = runtime.next_periodic
            else:
                report_at = None  # ON CONTENT CHANGE reports at messages and heartbeats (_tick)
            # closes before the next report only move the watermark: pass them in one go
            quiet_until = ts if report_at is None else min(ts, report_at - 1)
            if close <= quiet_until:
                runtime.closed_until = (quiet_until // step) * step
                runtime.next_close = runtime.closed_until + step
                self._evict(runtime)
                continue
            if report_at is None or report_at > ts:
                break
            if not self._catch_up(runtime, report_at, ts, period or step, report, collected):
                self._instant(runtime, report_at, (report_at // step) * step, report, collected)
                if report_at == close:
                    runtime.closed_until = close
                    runtime.next_close = close + step
                    self._evict(runtime)
                if period and report_at == runtime.next_periodic:
                    runtime.next_periodic = report_at + period

    def _catch_up(self, runtime: QueryRuntime, instant: int, ts: int, every: int, report: dict[str, Any],
                  collected: list[ResultEvent] | None) -> bool:
        """Over a long empty stretch, report its first ``max_catchup_windows - 1`` windows and its
        last one (which carries ``skipped``); True when it did (and moved the clock past it)."""
        limit = max(2, self.settings.max_catchup_windows)
        last = instant + ((ts - instant) // every) * every
        remaining = (last - instant) // every + 1
        if remaining <= limit or not self._empty_from(runtime, instant):
            return False
        step = runtime.step
        assert step is not None
        for k in range(limit - 1):
            t = instant + k * every
            self._instant(runtime, t, (t // step) * step, report, collected)
        skipped = remaining - limit
        runtime.stats["skipped_windows"] += skipped
        self._instant(runtime, last, (last // step) * step, report, collected, skipped=skipped)
        runtime.closed_until = (last // step) * step
        runtime.next_close = runtime.closed_until + step
        if runtime.next_periodic is not None:
            runtime.next_periodic = last + every
        self._evict(runtime)
        return True

    def _empty_from(self, runtime: QueryRuntime, instant: int) -> bool:
        """Is the window at ``instant`` empty, and so every later one up to the clock?"""
        end = _window_end(instant, runtime.step)
        for w in runtime.windows:
            buffer = runtime.buffers[w.stream]
            if not buffer.stamps:
                continue
            if not w.is_time or w.range_ms is None:
                return False
            if buffer.stamps[-1] >= end - w.range_ms:
                return False
        return True

    def _tick(self, runtime: QueryRuntime, instant: int, report: dict[str, Any],
              collected: list[ResultEvent] | None) -> None:
        """ON CONTENT CHANGE: report the current window if its content changed since the last report."""
        step = runtime.step
        if step is None or runtime.next_close is None:
            return
        end = _window_end(instant, step)
        starts = tuple(end - (w.range_ms or 0) if w.is_time else None for w in runtime.windows)
        changed = runtime.cc_dirty or runtime.cc_starts is None
        if not changed and runtime.cc_starts is not None:
            # something expired: the oldest triple last reported is before the window's new start
            changed = any(first is not None and start is not None and first < start
                          for first, start in zip(runtime.cc_starts, starts))
        if not changed:
            return
        runtime.cc_dirty = False
        runtime.cc_starts = tuple(runtime.buffers[w.stream].first_at_or_after(start, instant) if start is not None
                                  else None for w, start in zip(runtime.windows, starts))
        self._instant(runtime, instant, runtime.closed_until, report, collected)

    def _evict(self, runtime: QueryRuntime) -> None:
        """Keep what the next windows need (time ranges from the next close, the last n triples)."""
        for stream, buffer in runtime.buffers.items():
            before: int | None = None
            keep = 0
            has_time = False
            for w in runtime.windows:
                if w.stream != stream:
                    continue
                if w.is_time:
                    has_time = True
                    if w.range_ms is None or runtime.next_close is None:
                        before = None
                        break
                    start = runtime.next_close - w.range_ms
                    before = start if before is None else min(before, start)
                else:
                    keep = max(keep, w.triples or 0)
            if has_time and before is None:
                continue  # a range is unknown (unbound parameter): keep everything (bounded anyway)
            buffer.evict(before if has_time else None, keep)

    # -- evaluation ----------------------------------------------------------------------------------
    def _bind_params(self, runtime: QueryRuntime) -> bool:
        """(Re)bind parameters; recompile the fast path when a value changed. False if unbound."""
        if runtime.plan_text is not None and runtime.param_version == self.ontology.version \
                and runtime.param_error is None:
            return True  # the ontology did not change since the last binding
        values: dict[str, str] = {}
        try:
            for spec in runtime.query.params:
                values[spec.name] = self.ontology.bind(spec)
            windows = _bind_ranges(runtime.query.windows, values)
        except ParamError as exc:
            runtime.param_error = str(exc)
            return bool(runtime.param_values) or not runtime.query.params
        runtime.param_error = None
        runtime.param_version = self.ontology.version
        if values != runtime.param_values or runtime.plan_text is None:
            runtime.param_values = values
            if windows != runtime.windows or runtime.plan_text is None:
                runtime.windows = windows
                for stream, buffer in runtime.buffers.items():
                    mine = [w for w in windows if w.stream == stream and w.is_time]
                    ranges = [w.range_ms for w in mine if w.range_ms]
                    buffer.set_pane(pane_size(runtime.step, ranges) if mine and len(ranges) == len(mine) else None)
            text = runtime.query.executable(values)
            runtime.plan_text = text
            runtime.plan, runtime.not_compilable = None, None
            runtime.empty_cache = None
            if self.settings.fast_path:
                if any(w.name is not None for w in runtime.windows):
                    runtime.not_compilable = "named windows (WINDOW/GRAPH patterns) go the general way"
                else:
                    try:
                        runtime.plan = compile_query(text)
                    except NotCompilable as exc:
                        runtime.not_compilable = str(exc)
        return True

    def window_data(self, runtime: QueryRuntime, end: int, at: int | None = None,
                    sealed_until: int | None = None) -> WindowData:
        """The content the query sees for the window ending at ``end`` (up to instant ``at``)."""
        at = end if at is None else at
        step = runtime.step
        start = end - runtime.max_range() if step else end
        data = WindowData(start_ms=start, end_ms=end, at_ms=None if at == end else at)
        default_parts: list[dict[Triple, int]] = []
        default_segments: list[Any] | None = None
        n_default = sum(1 for w in runtime.windows if w.name is None)
        for w in runtime.windows:
            buffer = runtime.buffers[w.stream]
            if w.is_time:
                segments = buffer.time_segments(end - (w.range_ms or 0), at, sealed_until)
            else:
                segments = [buffer.last_triples(w.triples or 0, at)]
            content = merge(segments)
            if w.name is None:
                default_parts.append(content)
                if n_default == 1:
                    default_segments = segments
            else:
                data.windows[w.name] = content
        data.stamped = merge_latest(default_parts)
        data.segments = default_segments
        if not step:
            stamps = [ts for part in [data.stamped, *data.windows.values()] for ts in part.values()]
            data.start_ms = min(stamps) if stamps else end
        data.static = self._static_for(runtime)
        data.named = {iri: self._graph(iri) for iri in runtime.query.named_graphs}
        return data

    def _static_for(self, runtime: QueryRuntime) -> frozenset[Triple]:
        graphs = runtime.query.static_graphs
        if not graphs:
            return frozenset()
        key = (self.ontology.version, self._static_version)
        if runtime.static_cache is None or runtime.static_cache[0] != key:
            static: set[Triple] = set()
            for iri in graphs:
                static |= self._graph(iri)
            if runtime.relevant is not None:
                static = {t for t in static if t[1] in runtime.relevant}
            runtime.static_cache = (key, frozenset(static))
        return runtime.static_cache[1]

    def _instant(self, runtime: QueryRuntime, instant: int, sealed_until: int | None, report: dict[str, Any],
                 collected: list[ResultEvent] | None, skipped: int = 0) -> None:
        """Evaluate and report the query's current window at ``instant`` (content: timestamps < it)."""
        self.ontology.refresh()
        if not self._bind_params(runtime):
            runtime.stats["errors"] += 1
            runtime.last_error = runtime.param_error
            self._publish({"kind": "error", "query": runtime.query.name, "error": runtime.param_error})
            return
        end = _window_end(instant, runtime.step)
        data = self.window_data(runtime, end, instant, sealed_until)
        if runtime.query.report.non_empty and data.empty:
            runtime.stats["empty_windows"] += 1
            self._emit(runtime, instant, [], report, collected)
            return
        started = time.perf_counter()
        try:
            evaluation = self._run(runtime, data)
        except Exception as exc:
            runtime.stats["errors"] += 1
            runtime.last_error = f"window ending {end}: {exc}"
            log.warning("query %s failed on the window ending at %d: %s", runtime.query.name, end, exc)
            self._publish({"kind": "error", "query": runtime.query.name, "error": runtime.last_error})
            report["evaluated"] += 1
            return
        elapsed = (time.perf_counter() - started) * 1000
        runtime.eval_ms.append(elapsed)
        runtime.stats["windows"] += 1
        report["evaluated"] += 1
        runtime.stats["fast" if evaluation.path == "fast" else "general"] += 1
        if data.empty:
            runtime.stats["empty_windows"] += 1
        rows = [{k: canonical_term(v) for k, v in row.items()} for row in evaluation.rows]
        if not runtime.query.ordered:
            rows = sort_rows(rows, evaluation.variables)
        reported = stream_diff(rows, runtime.last_rows, runtime.query.r2s)
        runtime.last_rows = rows
        event = self._result_event(runtime, data, evaluation, reported, elapsed, skipped)
        runtime.stats["reported"] += 1
        report["reported"] = report.get("reported", 0) + 1
        runtime.results.append(event)
        if event["solutions"]:
            runtime.stats["results"] += 1
            runtime.nonempty.append(event)
        if collected is not None:
            collected.append(event)
        self._publish(event)
        if runtime.binding is not None and event["solutions"] and runtime.query.form in ("SELECT", "CONSTRUCT"):
            self._feed_rules(runtime, reported, data, instant)
        if runtime.query.output_stream:
            self._emit(runtime, instant, rows_to_triples(reported), report, collected)

    def _emit(self, runtime: QueryRuntime, instant: int, triples: list[Triple], report: dict[str, Any],
              collected: list[ResultEvent] | None) -> None:
        """A REGISTER STREAM query's output at ``instant`` (empty: the derived stream's clock moves)."""
        stream = runtime.query.output_stream
        if not stream:
            return
        runtime.stats["derived_triples"] += len(triples)
        if triples:
            report["derived"] = report.get("derived", 0) + 1
        self._ingest(stream, instant, [canonical_triple(t) for t in triples], report, collected)

    def _run(self, runtime: QueryRuntime, data: WindowData) -> Evaluation:
        if data.empty:  # an empty window's answer depends only on the static graphs and parameters
            key = (self.ontology.version, self._static_version, runtime.plan_text)
            if runtime.empty_cache is not None and runtime.empty_cache[0] == key:
                cached = runtime.empty_cache[1]
                return Evaluation(list(cached.variables), list(cached.rows), cached.path)
            evaluation = self._run_uncached(runtime, data)
            runtime.empty_cache = (key, evaluation)
            return evaluation
        return self._run_uncached(runtime, data)

    def _run_uncached(self, runtime: QueryRuntime, data: WindowData) -> Evaluation:
        if runtime.plan is not None:
            try:
                return run_plan(runtime.plan, data)
            except Fallback:
                runtime.stats["fallbacks"] += 1
        return evaluate_oxigraph(runtime.plan_text or runtime.query.sparql, data)

    def _result_event(self, runtime: QueryRuntime, data: WindowData, evaluation: Evaluation, rows: list[Row],
                      elapsed_ms: float, skipped: int) -> ResultEvent:
        query = runtime.query
        runtime.seq += 1
        window: dict[str, Any] = {"start": data.start_ms, "end": data.end_ms, "triples": data.size}
        if data.at_ms is not None:
            window["at"] = data.at_ms
        if query.form == "ASK":
            solutions = int(bool(rows) and rows[0].get("ask") is not None and rows[0]["ask"].value == "true")
        else:
            solutions = len(rows)
        payload: dict[str, Any] = {
            "kind": "result",
            "query": query.name,
            "seq": runtime.seq,
            "window": window,
            "variables": evaluation.variables,
            "rows": plain_rows(rows),
            "solutions": solutions,
            "path": evaluation.path,
            "eval_ms": round(elapsed_ms, 3),
        }
        if query.r2s != "RSTREAM":
            payload["operator"] = query.r2s
        if skipped:
            payload["skipped"] = skipped
        return ResultEvent(payload, rows, query.form)

    def _feed_rules(self, runtime: QueryRuntime, rows: list[Row], data: WindowData, instant: int) -> None:
        """Fires the binding's rule set on this window's rows, on the binding's own thread
        (:class:`BindingFirer`): answered here when it ends within ``streams.binding_wait_s``,
        else published when it ends; a window behind a fire in flight waits as the one pending
        fire, and a newer one replaces it (reported as ``skipped``)."""
        binding = runtime.binding
        assert binding is not None
        if runtime.query.form == "CONSTRUCT":
            rows = triples_as_facts(rows)
        try:
            facts = binding_facts(binding, rows, runtime.field_types, data, self.providers, runtime.handled)
        except Exception as exc:
            self._rule_error(runtime, binding, exc)
            return
        if not facts:
            return  # every row was a repeat: nothing new to decide
        window = {"start": data.start_ms, "end": data.end_ms}
        if self.inline_fires:
            try:
                result = self._fire_binding(runtime, binding, facts, instant, window)
            except Exception as exc:
                self._rule_error(runtime, binding, exc)
                return
            self._publish_actions(runtime, binding, facts, window, result)
            return
        job = Job(lambda: self._fire_binding(runtime, binding, facts, instant, window),
                  lambda result, error: self._late(runtime, binding, facts, window, result, error),
                  lambda: self._skipped(runtime, binding, window))
        if runtime.firer is None:
            runtime.firer = BindingFirer(runtime.query.name, self.settings.binding_wait_s)
        try:
            done, result = runtime.firer.fire(job)
        except Exception as exc:
            self._rule_error(runtime, binding, exc)
            return
        if done:
            self._publish_actions(runtime, binding, facts, window, result)

    def _fire_binding(self, runtime: QueryRuntime, binding: RuleBinding, facts: list[dict[str, Any]], instant: int,
                      window: dict[str, int]) -> Any:
        """One window's fire, on the binding's thread (a stateful binding's session is used by it alone)."""
        name = runtime.query.name
        correlation = f"{name}@{window['end']}"
        if binding.mode == "stateful":
            if runtime.session is None:
                if runtime.binding is not binding:  # unbound meanwhile: open no session for it
                    raise BindingError(f"the binding of {name!r} to {binding.ruleset!r} was removed")
                runtime.session = self.rules_engine.open_session(binding.ruleset, on_deploy=binding.on_deploy)
            # insert stamped with the evaluation instant (the clock moves there first) and fire: one JVM call
            result = runtime.session.push(facts, instant)
            context = {"query": name, "window": window, "session": runtime.session.id}  # not replayable alone
        else:
            result = self.rules_engine.fire(binding.ruleset, facts, record=False)
            context = {"query": name, "window": window}
        self.rules_engine.recorder.record(result, facts, origin="stream", correlation_id=correlation, context=context)
        return result

    def _publish_actions(self, runtime: QueryRuntime, binding: RuleBinding, facts: list[dict[str, Any]],
                         window: dict[str, int], result: Any, late: bool = False) -> None:
        runtime.stats["rule_fires"] += 1
        payload = result.to_dict() if hasattr(result, "to_dict") else dict(result)
        event = {
            "kind": "actions", "query": runtime.query.name, "ruleset": binding.ruleset, "version": payload.get("version"),
            "decision_id": payload.get("decision_id"), "window": window, "facts": facts,
            "actions": payload.get("actions", []), "fired": payload.get("fired", []), "dispatch": binding.dispatch,
        }
        if late:
            event["late"] = True
        self._publish(event)

    def _late(self, runtime: QueryRuntime, binding: RuleBinding, facts: list[dict[str, Any]], window: dict[str, int],
              result: Any, error: BaseException | None) -> None:
        """A fire that outlasted ``streams.binding_wait_s`` (or waited behind one) reports itself."""
        with self._lock:
            runtime.stats["rule_late"] += 1
            if error is not None:
                self._rule_error(runtime, binding, error)
            else:
                self._publish_actions(runtime, binding, facts, window, result, late=True)

    def _skipped(self, runtime: QueryRuntime, binding: RuleBinding, window: dict[str, int]) -> None:
        """A window replaced by a newer one while the binding's fire was in flight: said, not silent."""
        runtime.stats["rule_skipped"] += 1
        self._publish({"kind": "skipped", "query": runtime.query.name, "ruleset": binding.ruleset, "window": window,
                       "reason": f"the rules of {binding.ruleset!r} were still firing an earlier window; "
                                 "a newer window replaced this one (streams.binding_wait_s)"})

    def _rule_error(self, runtime: QueryRuntime, binding: RuleBinding, exc: BaseException) -> None:
        name = runtime.query.name
        runtime.stats["rule_errors"] += 1
        runtime.last_error = f"rules {binding.ruleset!r}: {exc}"
        log.warning("query %s: firing %s failed: %s", name, binding.ruleset, exc)
        self._publish({"kind": "error", "query": name, "error": runtime.last_error})

    def _stop_binding(self, runtime: QueryRuntime) -> None:
        """Stops the binding's thread (after its fire in flight) and closes its session."""
        if runtime.firer is not None:
            runtime.firer.close()
            runtime.firer = None
        if runtime.session is not None:
            self._close_session(runtime.session)
            runtime.session = None

    def _close_session(self, session: Any) -> None:
        closer = getattr(self.rules_engine, "close_session", None)
        try:
            closer(session.id) if closer is not None and hasattr(session, "id") else session.close()
        except Exception:  # closing a dead session must not hide the real work
            log.debug("closing a rules session failed", exc_info=True)

    def close(self) -> None:
        with self._lock:
            for runtime in self._queries.values():
                self._stop_binding(runtime)


def _with_attributes(relevant: frozenset[NamedNode] | None, binding: RuleBinding) -> frozenset[NamedNode] | None:
    """What a query keeps of its streams, plus the properties its binding reads from the window
    (``attributes``: a detected customer's age is not in the query, but the rules need it)."""
    if relevant is None or not binding.attributes:
        return relevant
    return relevant | {parse_node(p, "attributes", DEFAULT_PREFIXES) for p in binding.attributes.values()}


def _window_end(instant: int, step: int | None) -> int:
    """The end of the window current at ``instant``: the first close at or after it."""
    if not step:
        return instant
    return -(-instant // step) * step


_TYPED = re.compile(r'^"((?:[^"\\]|\\.)*)"\^\^<([^>]*)>$')


def _bind_ranges(windows: list[WindowSpec], values: dict[str, str]) -> list[WindowSpec]:
    """Windows with ``[RANGE ?param …]`` resolved from the parameter values (seconds, or an xsd:duration)."""
    out = []
    for w in windows:
        if w.range_param is None:
            out.append(w)
            continue
        text = values.get(w.range_param)
        if text is None:
            raise ParamError(f"?{w.range_param}: no value for the window range")
        ms = _range_ms(w.range_param, text)
        if w.step_ms is not None and ms < w.step_ms:
            raise ParamError(f"?{w.range_param} = {ms} ms is shorter than the window's STEP ({w.step_ms} ms)")
        out.append(WindowSpec(w.stream, ms, w.step_ms, w.triples, w.name, w.range_param, w.line, w.column))
    return out


def _range_ms(name: str, text: str) -> int:
    match = _TYPED.match(text)
    lexical, datatype = (match.group(1), match.group(2)) if match else (text.strip('"'), None)
    try:
        if datatype in (XSD + "duration", XSD + "dayTimeDuration") or lexical.startswith("P"):
            return duration_ms(lexical)
        seconds = canonical_term(Literal(lexical, datatype=NamedNode(datatype or XSD + "decimal")))
        from decimal import Decimal

        ms = Decimal(seconds.value) * 1000  # type: ignore[union-attr]
    except Exception:
        raise ParamError(f"?{name} = {text}: a window range must be a number of seconds or a duration like "
                         "\"PT10S\"^^xsd:dayTimeDuration") from None
    if ms <= 0 or ms != ms.to_integral_value():
        raise ParamError(f"?{name} = {text}: a window range must be a positive whole number of milliseconds")
    return int(ms)


def _select_variables(query: ContinuousQuery) -> list[str]:
    """The projected variables (from the SPARQL engine's view of the query)."""
    return evaluate_oxigraph(query.executable({p.name: '""' for p in query.params}), WindowData(0, 0)).variables


def _positioned(message: str) -> QueryParseError:
    """pyoxigraph's "error at L:C: …" as a QueryParseError with line and column."""
    match = re.match(r"error at (\d+):(\d+): (.*)", message, re.S)
    if match:
        return QueryParseError(match.group(3).strip(), int(match.group(1)), int(match.group(2)))
    return QueryParseError(message, 0, 0)


__all__ = ["QueryNotFound", "QueryRuntime", "StreamEngine", "StreamError", "Term"]
