"""The evaluator: one query's window at one instant, from its buffers and the static graphs to the
reported result event.

Why apart from the scheduler: *when* a window is evaluated (closes, reports, catch-up) is the
scheduler's business (:mod:`gateway.stream.scheduler`); *what* it holds and answers is this
module's — parameters bound from the ontology, the window's content, the fast path or the general
SPARQL path, the R2S operator, and the counters of the query. It never publishes and never fires:
it hands back a :class:`WindowOutcome` and the scheduler says what happens next.
"""

from __future__ import annotations

import logging
import re
import time
from dataclasses import dataclass
from decimal import Decimal
from typing import Any

from pyoxigraph import Literal, NamedNode

from gateway.config import StreamSettings
from gateway.rdf.terms import XSD, Triple, canonical_term, canonical_triple
from gateway.stream.evaluate import Evaluation, WindowData, evaluate_oxigraph
from gateway.stream.fastpath import Fallback, NotCompilable, compile_query, run_plan
from gateway.stream.lexer import QueryParseError
from gateway.stream.params import OntologySource, ParamError
from gateway.stream.query import ContinuousQuery, WindowSpec, duration_ms
from gateway.stream.query_state import QueryRuntime
from gateway.stream.results import ResultEvent, Row, plain_rows, rows_to_triples, sort_rows, stream_diff
from gateway.stream.windows import merge, merge_latest, pane_size

log = logging.getLogger(__name__)

MAX_FAST_SKIP = 32
"""The most windows one run of fallbacks leaves to the general path before the fast path is tried again."""


@dataclass
class WindowOutcome:
    """What one evaluation instant gave: ``evaluated`` (counts in the push report); ``error`` (to
    publish); ``event`` (the reported result, with ``rows`` and ``data`` for a rule binding);
    ``derived`` (a REGISTER STREAM's triples at this instant; None: nothing to emit)."""

    evaluated: bool = False
    error: str | None = None
    event: ResultEvent | None = None
    rows: list[Row] | None = None
    data: WindowData | None = None
    derived: list[Triple] | None = None


class Evaluator:
    """Static graphs, parameter binding and window evaluation for the queries of one stream engine."""

    def __init__(self, settings: StreamSettings, ontology: OntologySource) -> None:
        self.settings = settings
        self.ontology = ontology
        self._static: dict[str, frozenset[Triple]] = {}
        self.static_version = 0
        self._ontology_canonical: tuple[int, frozenset[Triple]] | None = None

    # -- static graphs -----------------------------------------------------------------------------
    def add_static_graph(self, iri: str, triples: set[Triple] | frozenset[Triple]) -> None:
        self._static[iri] = frozenset(canonical_triple(t) for t in triples)
        self.static_version += 1

    def share_static_graphs(self, other: "Evaluator") -> None:
        """Use ``other``'s static graphs (a scratch engine that checks queries for it)."""
        self._static = other._static

    def graph(self, iri: str) -> frozenset[Triple]:
        if iri == self.settings.ontology_graph:
            triples = self.ontology.triples
            version = self.ontology.version
            if self._ontology_canonical is None or self._ontology_canonical[0] != version:
                self._ontology_canonical = (version, frozenset(canonical_triple(t) for t in triples))
            return self._ontology_canonical[1]
        return self._static[iri]

    def known_graphs(self) -> list[str]:
        return sorted(set(self._static) | {self.settings.ontology_graph})

    # -- parameters ----------------------------------------------------------------------------------
    def bind_params(self, runtime: QueryRuntime) -> bool:
        """(Re)bind parameters; recompile the fast path when a value changed. False if unbound."""
        if runtime.plan_text is not None and runtime.param_version == self.ontology.version \
                and runtime.param_error is None:
            return True  # the ontology did not change since the last binding
        values: dict[str, str] = {}
        try:
            for spec in runtime.query.params:
                values[spec.name] = self.ontology.bind(spec)
            windows = bind_ranges(runtime.query.windows, values)
        except ParamError as exc:
            runtime.param_error = str(exc)
            return bool(runtime.param_values) or not runtime.query.params
        runtime.param_error = None
        runtime.param_version = self.ontology.version
        if values != runtime.param_values or runtime.plan_text is None:
            runtime.param_values = values
            if windows != runtime.windows or runtime.plan_text is None:
                self._set_windows(runtime, windows)
            self._compile(runtime, runtime.query.executable(values))
        return True

    @staticmethod
    def _set_windows(runtime: QueryRuntime, windows: list[WindowSpec]) -> None:
        runtime.windows = windows
        for stream, buffer in runtime.buffers.items():
            mine = [w for w in windows if w.stream == stream and w.is_time]
            ranges = [w.range_ms for w in mine if w.range_ms]
            buffer.set_pane(pane_size(runtime.step, ranges) if mine and len(ranges) == len(mine) else None)

    def _compile(self, runtime: QueryRuntime, text: str) -> None:
        runtime.plan_text = text
        runtime.plan, runtime.not_compilable = None, None
        runtime.empty_cache = None
        runtime.fast_skip = runtime.fast_backoff = 0
        if not self.settings.fast_path:
            return
        if any(w.name is not None for w in runtime.windows):
            runtime.not_compilable = "named windows (WINDOW/GRAPH patterns) go the general way"
            return
        try:
            runtime.plan = compile_query(text)
        except NotCompilable as exc:
            runtime.not_compilable = str(exc)

    # -- a window's content --------------------------------------------------------------------------
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
        data.named = {iri: self.graph(iri) for iri in runtime.query.named_graphs}
        return data

    def _static_for(self, runtime: QueryRuntime) -> frozenset[Triple]:
        graphs = runtime.query.static_graphs
        if not graphs:
            return frozenset()
        key = (self.ontology.version, self.static_version)
        if runtime.static_cache is None or runtime.static_cache[0] != key:
            static: set[Triple] = set()
            for iri in graphs:
                static |= self.graph(iri)
            if runtime.relevant is not None:
                static = {t for t in static if t[1] in runtime.relevant}
            runtime.static_cache = (key, frozenset(static))
        return runtime.static_cache[1]

    # -- evaluation ----------------------------------------------------------------------------------
    def evaluate(self, runtime: QueryRuntime, instant: int, sealed_until: int | None, skipped: int = 0) -> WindowOutcome:
        """Evaluate the query's current window at ``instant`` (content: timestamps < it) and keep
        its result; the caller publishes, feeds the binding and emits the derived triples."""
        self.ontology.refresh()
        if not self.bind_params(runtime):
            runtime.stats["errors"] += 1
            runtime.last_error = runtime.param_error
            return WindowOutcome(error=runtime.param_error)
        end = window_end(instant, runtime.step)
        data = self.window_data(runtime, end, instant, sealed_until)
        if runtime.query.report.non_empty and data.empty:
            runtime.stats["empty_windows"] += 1
            return WindowOutcome(derived=[])
        started = time.perf_counter()
        try:
            evaluation = self._run(runtime, data)
        except Exception as exc:
            runtime.stats["errors"] += 1
            runtime.last_error = f"window ending {end}: {exc}"
            log.warning("query %s failed on the window ending at %d: %s", runtime.query.name, end, exc)
            return WindowOutcome(evaluated=True, error=runtime.last_error)
        elapsed = (time.perf_counter() - started) * 1000
        runtime.eval_ms.append(elapsed)
        runtime.stats["windows"] += 1
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
        runtime.results.append(event)
        if event["solutions"]:
            runtime.stats["results"] += 1
            runtime.nonempty.append(event)
        derived = rows_to_triples(reported) if runtime.query.output_stream else None
        return WindowOutcome(evaluated=True, event=event, rows=reported, data=data, derived=derived)

    def _run(self, runtime: QueryRuntime, data: WindowData) -> Evaluation:
        if data.empty:  # an empty window's answer depends only on the static graphs and parameters
            key = (self.ontology.version, self.static_version, runtime.plan_text)
            if runtime.empty_cache is not None and runtime.empty_cache[0] == key:
                cached = runtime.empty_cache[1]
                return Evaluation(list(cached.variables), list(cached.rows), cached.path)
            evaluation = self._run_uncached(runtime, data, may_skip=False)  # tried as itself, never skipped
            if evaluation.path == "fast" or runtime.plan is None:
                # a general answer of a query with a fast path (it fell back) is not kept: the next
                # empty window tries the fast path again, so only fallbacks leave it (stats agree)
                runtime.empty_cache = (key, evaluation)
            return evaluation
        return self._run_uncached(runtime, data)

    @staticmethod
    def _run_uncached(runtime: QueryRuntime, data: WindowData, may_skip: bool = True) -> Evaluation:
        """The fast path's answer, or the general path's when the fast path cannot decide exactly.

        Why the back-off: what makes a window fall back is usually the shape of the stream's data
        (doubles in arithmetic, e.g. every Entrance reading's distances), so the next window falls
        back too, and a try that fails costs more than the general path itself (1.5 ms against
        1.1 ms per CustomerDetectionQuery window, on the ROS reading → Speak path). So after a
        fallback the next 1, 2, 4, … up to :data:`MAX_FAST_SKIP` windows go to the general path
        straight away (``stats.fast_skipped``; counted in ``stats.fallbacks`` too: left to the
        general path), and one window that the fast path decides starts the count again at 1.
        Both paths answer the same, so this changes only what a window costs. An empty window is
        never skipped (``may_skip``): its answer is cached for the empty windows after it, which
        must not count as left to the general path when nothing made them fall back."""
        if runtime.plan is not None:
            if may_skip and runtime.fast_skip > 0:
                runtime.fast_skip -= 1
                runtime.stats["fast_skipped"] += 1
                runtime.stats["fallbacks"] += 1
            else:
                try:
                    evaluation = run_plan(runtime.plan, data)
                except Fallback:
                    runtime.stats["fallbacks"] += 1
                    runtime.fast_backoff = min(max(1, 2 * runtime.fast_backoff), MAX_FAST_SKIP)
                    runtime.fast_skip = runtime.fast_backoff
                else:
                    runtime.fast_backoff = 0
                    return evaluation
        return evaluate_oxigraph(runtime.plan_text or runtime.query.sparql, data)

    @staticmethod
    def _result_event(runtime: QueryRuntime, data: WindowData, evaluation: Evaluation, rows: list[Row],
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


def window_end(instant: int, step: int | None) -> int:
    """The end of the window current at ``instant``: the first close at or after it."""
    if not step:
        return instant
    return -(-instant // step) * step


_TYPED = re.compile(r'^"((?:[^"\\]|\\.)*)"\^\^<([^>]*)>$')


def bind_ranges(windows: list[WindowSpec], values: dict[str, str]) -> list[WindowSpec]:
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
        ms = Decimal(seconds.value) * 1000  # type: ignore[union-attr]
    except Exception:
        raise ParamError(f"?{name} = {text}: a window range must be a number of seconds or a duration like "
                         "\"PT10S\"^^xsd:dayTimeDuration") from None
    if ms <= 0 or ms != ms.to_integral_value():
        raise ParamError(f"?{name} = {text}: a window range must be a positive whole number of milliseconds")
    return int(ms)


def select_variables(query: ContinuousQuery) -> list[str]:
    """The projected variables (from the SPARQL engine's view of the query)."""
    return evaluate_oxigraph(query.executable({p.name: '""' for p in query.params}), WindowData(0, 0)).variables


def positioned(message: str) -> QueryParseError:
    """pyoxigraph's "error at L:C: …" as a QueryParseError with line and column."""
    match = re.match(r"error at (\d+):(\d+): (.*)", message, re.S)
    if match:
        return QueryParseError(match.group(3).strip(), int(match.group(1)), int(match.group(2)))
    return QueryParseError(message, 0, 0)
