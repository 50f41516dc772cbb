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

The engine is the registry and the front door (register, bind, push, advance, subscribe); the
work is done by three parts, each in its own module:

- :mod:`gateway.stream.scheduler` — which windows a message or heartbeat closes (under the lock);
- :mod:`gateway.stream.evaluator` — what a window holds and answers;
- :mod:`gateway.stream.subscriber` — a rule binding's fire, handed over after the lock is released
  (a slow rule set never holds up the stream).
"""

from __future__ import annotations

import itertools
import logging
import threading
from collections import deque
from collections.abc import Callable
from typing import Any

from pyoxigraph import Literal, NamedNode

from gateway.config import StreamSettings, ontology_file
from gateway.rdf.terms import DEFAULT_PREFIXES, Term, Triple, canonical_triple, parse_node
from gateway.stream.analysis import construct_fields, relevant_predicates
from gateway.stream.evaluate import WindowData, check_sparql
from gateway.stream.evaluator import Evaluator, positioned, select_variables
from gateway.stream.lexer import QueryParseError, position
from gateway.stream.params import OntologySource
from gateway.stream.query import ContinuousQuery, ParamSpec, ReportPolicy, parse_query
from gateway.stream.query_state import QueryRuntime
from gateway.stream.results import ResultEvent, to_sparql_json
from gateway.stream.rules import BindingError, RuleBinding, check_binding
from gateway.stream.scheduler import Pass, Scheduler
from gateway.stream.subscriber import BindingSubscriber, same_session
from gateway.stream.windows import StreamBuffer

log = logging.getLogger(__name__)

Subscriber = Callable[[dict[str, Any]], None]
InputListener = Callable[[str, int, list[Triple]], None]


class StreamError(ValueError):
    """A request the stream engine refuses (unknown query, too many queries, …)."""


class QueryNotFound(StreamError):
    pass


class StreamEngine:
    """Registers queries, takes timestamped triples, evaluates windows and publishes results."""

    def __init__(self, settings: StreamSettings | None = None, rules_engine: Any = None,
                 ontology: OntologySource | None = None,
                 providers: dict[str, Callable[[], list[dict[str, Any]]]] | None = None) -> None:
        self.settings = settings or StreamSettings()
        self.rules_engine = rules_engine
        self.providers = dict(providers or {})  # context facts a binding can ask for (e.g. "robots")
        self.ontology = ontology if ontology is not None else OntologySource(ontology_file(self.settings.knowledge_dir))
        self._queries: dict[str, QueryRuntime] = {}
        self._subscribers: dict[int, tuple[Subscriber, str | None, bool]] = {}
        self._input_listeners: list[InputListener] = []
        self._ids = itertools.count(1)
        self._lock = threading.RLock()  # the registry, the clocks and the buffers
        self._publish_lock = threading.RLock()  # one subscriber call at a time (also from binding threads)
        self.subscriber_errors = 0
        self.evaluator = Evaluator(self.settings, self.ontology)
        self.bindings = BindingSubscriber(self.settings, rules_engine, self.providers, self._publish, self._publish_lock)
        self.scheduler = Scheduler(self.settings, self.evaluator, self._queries, self._publish, self.bindings.prepare)

    @property
    def inline_fires(self) -> bool:
        """A replay's scratch engine fires its bindings on the pushing thread, in window order: no
        binding thread, no skipped or late window (see gateway.stream.replay)."""
        return self.bindings.inline

    @inline_fires.setter
    def inline_fires(self, value: bool) -> None:
        self.bindings.inline = bool(value)

    @property
    def stream_stats(self) -> dict[str, dict[str, int]]:
        return self.scheduler.stream_stats

    @property
    def _order(self) -> list[QueryRuntime]:
        return self.scheduler.order

    # -- static graphs -----------------------------------------------------------------------------
    def add_static_graph(self, iri: str, triples: set[Triple] | frozenset[Triple]) -> None:
        """Make ``triples`` available as ``FROM <iri>`` / ``FROM NAMED <iri>`` to queries."""
        with self._lock:
            self.evaluator.add_static_graph(iri, triples)

    def share_static_graphs(self, other: "StreamEngine") -> None:
        """Use ``other``'s static graphs (a scratch engine that checks queries for it)."""
        self.evaluator.share_static_graphs(other.evaluator)

    def window_data(self, runtime: QueryRuntime, end: int, at: int | None = None,
                    sealed_until: int | None = None) -> WindowData:
        """The content the query sees for the window ending at ``end`` (up to instant ``at``)."""
        return self.evaluator.window_data(runtime, end, at, sealed_until)

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
            raise positioned(str(exc)) from None
        for iri in query.static_graphs + query.named_graphs:
            if iri not in self.evaluator.known_graphs():
                line, col = position(text, text.find(iri)) if iri in text else (0, 0)
                raise QueryParseError(f"unknown static graph <{iri}>; known: {self.evaluator.known_graphs()}", line, col)
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
            self.evaluator.bind_params(runtime)
            if binding is not None:
                self._check_binding(runtime, binding)
            old = self._queries.get(query.name)
            if old is not None:  # a new version of the query: a stateful binding to the same rules keeps its session
                self.bindings.stop(old, keep=same_session(old.binding, binding))
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
        self.scheduler.order = order

    def bind_rules(self, name: str, binding: RuleBinding | None) -> dict[str, Any]:
        """Bind (or with None, unbind) a query's (or a stream's) results to a rule set."""
        with self._lock:
            runtime = self._get(name)
            self.bindings.stop(runtime, keep=same_session(runtime.binding, binding))
            runtime.binding = None
            runtime.relevant = relevant_predicates(runtime.query.sparql)
            if binding is not None:
                self._check_binding(runtime, binding)
            return runtime.info()

    def _check_binding(self, runtime: QueryRuntime, binding: RuleBinding) -> None:
        if self.rules_engine is None:
            raise BindingError("no rules engine is configured")
        if runtime.query.form == "SELECT":
            variables = select_variables(runtime.query)
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
            self.bindings.stop(runtime)
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
        """Every subscriber that wants ``event``, one event at a time (results come from the
        pushing thread, actions also from a binding's thread: see gateway.stream.subscriber)."""
        solutions = event.get("solutions", 1)
        with self._publish_lock:
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
        events this message caused (``results``; see ``results.report_to_sparql_json``). The rule
        bindings' fires of those windows run after the stream lock is released."""
        ts = int(timestamp_ms)
        if len(triples) > self.settings.max_message_triples:
            raise StreamError(f"a message may hold at most {self.settings.max_message_triples} triples")
        run = Pass({"stream": stream, "timestamp": ts, "triples": len(triples), "queries": 0, "evaluated": 0,
                    "reported": 0, "late_for": [], "overflow_for": [], "derived": 0},
                   [] if with_results else None)
        canonical = [canonical_triple(t) if type(t[2]) is Literal else t for t in triples]
        with self._lock:
            for listener in self._input_listeners:
                try:
                    listener(stream, ts, canonical)
                except Exception:  # an observer must never stop the stream
                    self.subscriber_errors += 1
                    log.exception("stream input listener failed")
            self.scheduler.ingest(stream, ts, canonical, run, external=True)
            ticket = self.bindings.ticket() if run.fires else None
        if ticket is not None:
            self.bindings.deliver(ticket, run.fires)
        if run.collected is not None:
            run.report["results"] = run.collected
        return run.report

    def advance(self, timestamp_ms: int, stream: str | None = None) -> int:
        """Move the clock of the queries (reading ``stream``, or all) to ``timestamp_ms`` (a heartbeat);
        returns the number of windows evaluated."""
        run = Pass({"evaluated": 0, "reported": 0, "derived": 0})
        with self._lock:
            self.scheduler.heartbeat(int(timestamp_ms), stream, run)
            ticket = self.bindings.ticket() if run.fires else None
        if ticket is not None:
            self.bindings.deliver(ticket, run.fires)
        return run.report["evaluated"]

    def close(self) -> None:
        """Stops the bindings; their durable sessions are put away, not disposed (a restart or
        another process rebuilds them)."""
        with self._lock:
            for runtime in self._queries.values():
                self.bindings.stop(runtime, keep=True)


def _with_attributes(relevant: frozenset[NamedNode] | None, binding: RuleBinding) -> frozenset[NamedNode] | None:
    """What a query keeps of its streams, plus the properties its binding reads from the window
    (``attributes``: a detected customer's age is not in the query, but the rules need it)."""
    if relevant is None or not binding.attributes:
        return relevant
    return relevant | {parse_node(p, "attributes", DEFAULT_PREFIXES) for p in binding.attributes.values()}


__all__ = ["QueryNotFound", "QueryRuntime", "ResultEvent", "StreamEngine", "StreamError", "Term"]
