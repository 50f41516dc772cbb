"""A registered continuous query's state: its windows' buffers, clock, kept results, fast-path
plan, rule binding and counters.

Why its own module: the scheduler (:mod:`gateway.stream.scheduler`), the evaluator
(:mod:`gateway.stream.evaluator`) and the binding subscriber (:mod:`gateway.stream.subscriber`)
each work on one part of it; the engine (:mod:`gateway.stream.engine`) owns the registry.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Any

from pyoxigraph import NamedNode

from gateway.stream.binding_fire import BindingFirer
from gateway.stream.evaluate import Evaluation
from gateway.stream.fastpath import Plan
from gateway.stream.query import ContinuousQuery, WindowSpec
from gateway.stream.results import ResultEvent, Row
from gateway.stream.rules import RuleBinding
from gateway.stream.windows import StreamBuffer
from gateway.rdf.terms import Triple


def _new_stats() -> dict[str, int]:
    return {
        "windows": 0, "reported": 0, "empty_windows": 0, "skipped_windows": 0, "fast": 0, "general": 0,
        "fallbacks": 0, "results": 0, "late_dropped": 0, "overflow_dropped": 0, "errors": 0, "rule_fires": 0,
        "rule_errors": 0, "derived_triples": 0, "rule_skipped": 0, "rule_late": 0, "fast_skipped": 0,
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
    fast_skip: int = 0  # windows still left to the general path after a fallback (gateway.stream.evaluator)
    fast_backoff: int = 0  # how many the last fallback left there (doubles while windows keep falling back)
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
