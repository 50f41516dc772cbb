"""The scheduler: which windows a message or a heartbeat closes, and in what order they are reported.

Why its own module: event-time scheduling is the part of the stream engine with the subtle
semantics (docs/streams.md) — epoch-aligned closes, report policies (window close, content change,
periodic), bounded catch-up over long empty stretches (``skipped_windows``), late data dropped and
counted, buffers evicted to what the next windows need. It runs under the stream lock and asks the
:class:`~gateway.stream.evaluator.Evaluator` for each window; a window's fire for a rule binding is
only *prepared* here (``Pass.fires``) and handed to the bindings after the lock is released
(:mod:`gateway.stream.subscriber`).
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from gateway.config import StreamSettings
from gateway.rdf.terms import Triple, canonical_triple
from gateway.stream.evaluate import WindowData
from gateway.stream.evaluator import Evaluator, window_end
from gateway.stream.query_state import QueryRuntime
from gateway.stream.results import ResultEvent, Row
from gateway.stream.windows import StreamBuffer

log = logging.getLogger(__name__)

Publish = Callable[[dict[str, Any]], None]
# (runtime, reported rows, window data, instant) -> a prepared fire, or None (see BindingSubscriber.prepare)
PrepareFire = Callable[[QueryRuntime, list[Row], WindowData, int], Any]


@dataclass
class Pass:
    """One push or heartbeat under the stream lock: its report, the result events it collects
    (``with_results``), and the fires it prepared for the rule bindings, in window order."""

    report: dict[str, Any]
    collected: list[ResultEvent] | None = None
    fires: list[Any] = field(default_factory=list)


class Scheduler:
    """Moves the queries' clocks and evaluates the windows they close (called under the stream lock)."""

    def __init__(self, settings: StreamSettings, evaluator: Evaluator, queries: dict[str, QueryRuntime],
                 publish: Publish, prepare_fire: PrepareFire) -> None:
        self.settings = settings
        self.evaluator = evaluator
        self.queries = queries  # the engine's registry (shared, not copied)
        self.order: list[QueryRuntime] = []  # producers of derived streams before their consumers
        self.publish = publish
        self.prepare_fire = prepare_fire
        self.stream_stats: dict[str, dict[str, int]] = {}

    # -- input -------------------------------------------------------------------------------------
    def ingest(self, stream: str, ts: int, triples: list[Triple], run: Pass, external: bool = False) -> None:
        """One message of ``stream`` at ``ts``: every query reading it moves its clock there."""
        report = run.report
        if triples or external:
            stats = self.stream_stats.setdefault(stream, {"messages": 0, "triples": 0})
            stats["messages"] += 1
            stats["triples"] += len(triples)
        for runtime in list(self.order):
            buffer = runtime.buffers.get(stream)
            if buffer is None or runtime.query.name not in self.queries:
                continue
            if external:
                report["queries"] += 1
            if runtime.closed_until is not None and ts < runtime.closed_until:
                runtime.stats["late_dropped"] += 1
                if "late_for" in report:
                    report["late_for"].append(runtime.query.name)
                continue
            self.advance(runtime, ts, run)
            kept = triples if runtime.relevant is None else [t for t in triples if t[1] in runtime.relevant]
            if kept:
                buffer.add(ts, kept)
                runtime.cc_dirty = True
                if self._enforce_bound(runtime, buffer) and "overflow_for" in report:
                    report["overflow_for"].append(runtime.query.name)
            if runtime.step is None:  # only count windows: every message is an evaluation instant
                runtime.clock = ts if runtime.clock is None else max(runtime.clock, ts)
                if kept:
                    self.instant(runtime, ts + 1, ts + 1, run)
                runtime.closed_until = ts
                self._evict(runtime)
            elif runtime.query.report.trigger == "content_change":
                self.tick(runtime, ts + 1, run)

    def heartbeat(self, ts: int, stream: str | None, run: Pass) -> None:
        """Move the clock of the queries (reading ``stream``, or all) to ``ts``."""
        for runtime in list(self.order):
            if stream is not None and stream not in runtime.buffers:
                continue
            if runtime.closed_until is not None and ts < runtime.closed_until:
                continue
            self.advance(runtime, ts, run)
            if runtime.query.report.trigger == "content_change":
                self.tick(runtime, ts, run)

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
    def advance(self, runtime: QueryRuntime, ts: int, run: Pass) -> None:
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
                report_at = None  # ON CONTENT CHANGE reports at messages and heartbeats (tick)
            # closes before the next report only move the watermark: pass them in one go
            quiet_until = ts if report_at is None else min(ts, report_at - 1)
            if close <= quiet_until:
                runtime.closed_until = (quiet_until // step) * step
                runtime.next_close = runtime.closed_until + step
                self._evict(runtime)
                continue
            if report_at is None or report_at > ts:
                break
            if not self._catch_up(runtime, report_at, ts, period or step, run):
                self.instant(runtime, report_at, (report_at // step) * step, run)
                if report_at == close:
                    runtime.closed_until = close
                    runtime.next_close = close + step
                    self._evict(runtime)
                if period and report_at == runtime.next_periodic:
                    runtime.next_periodic = report_at + period

    def _catch_up(self, runtime: QueryRuntime, instant: int, ts: int, every: int, run: Pass) -> bool:
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
            self.instant(runtime, t, (t // step) * step, run)
        skipped = remaining - limit
        runtime.stats["skipped_windows"] += skipped
        self.instant(runtime, last, (last // step) * step, run, skipped=skipped)
        runtime.closed_until = (last // step) * step
        runtime.next_close = runtime.closed_until + step
        if runtime.next_periodic is not None:
            runtime.next_periodic = last + every
        self._evict(runtime)
        return True

    @staticmethod
    def _empty_from(runtime: QueryRuntime, instant: int) -> bool:
        """Is the window at ``instant`` empty, and so every later one up to the clock?"""
        end = window_end(instant, runtime.step)
        for w in runtime.windows:
            buffer = runtime.buffers[w.stream]
            if not buffer.stamps:
                continue
            if not w.is_time or w.range_ms is None:
                return False
            if buffer.stamps[-1] >= end - w.range_ms:
                return False
        return True

    def tick(self, runtime: QueryRuntime, instant: int, run: Pass) -> None:
        """ON CONTENT CHANGE: report the current window if its content changed since the last report."""
        step = runtime.step
        if step is None or runtime.next_close is None:
            return
        end = window_end(instant, step)
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
        self.instant(runtime, instant, runtime.closed_until, run)

    @staticmethod
    def _evict(runtime: QueryRuntime) -> None:
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

    # -- one evaluation instant ----------------------------------------------------------------------
    def instant(self, runtime: QueryRuntime, instant: int, sealed_until: int | None, run: Pass,
                skipped: int = 0) -> None:
        """Evaluate and report the query's window at ``instant``; prepare its binding's fire; feed
        a REGISTER STREAM's output to its stream."""
        outcome = self.evaluator.evaluate(runtime, instant, sealed_until, skipped)
        report = run.report
        if outcome.evaluated:
            report["evaluated"] += 1
        if outcome.error is not None:
            self.publish({"kind": "error", "query": runtime.query.name, "error": outcome.error})
        event = outcome.event
        if event is not None:
            report["reported"] = report.get("reported", 0) + 1
            if run.collected is not None:
                run.collected.append(event)
            self.publish(event)
            if outcome.rows is not None and outcome.data is not None:
                fire = self.prepare_fire(runtime, outcome.rows, outcome.data, instant)
                if fire is not None:
                    run.fires.append(fire)
        if outcome.derived is not None:
            self._emit(runtime, instant, outcome.derived, run)

    def _emit(self, runtime: QueryRuntime, instant: int, triples: list[Triple], run: Pass) -> None:
        """A REGISTER STREAM query's output at ``instant`` (empty: the derived stream's clock moves)."""
        stream = runtime.query.output_stream
        if not stream:
            return
        runtime.stats["derived_triples"] += len(triples)
        if triples:
            run.report["derived"] = run.report.get("derived", 0) + 1
        self.ingest(stream, instant, [canonical_triple(t) for t in triples], run)
