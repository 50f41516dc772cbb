"""Prometheus metrics of one app: fires, fire latency, deploys, errors (served at ``GET /metrics``).

Why a registry per app (not prometheus_client's global one): tests and embedders may build several
apps in one process; each must count its own traffic. Deploys are counted from the engine's
listener, so rule sets loaded from the filesystem or deployed by other modules are counted too.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

from prometheus_client import (
    CollectorRegistry,
    Counter,
    Gauge,
    Histogram,
    disable_created_metrics,
    generate_latest,
)
from prometheus_client.core import GaugeMetricFamily
from prometheus_client.registry import Collector

from gateway.engine.errors import FireTimeout, Overloaded

disable_created_metrics()  # no *_created series: they double the output and nobody graphs them

# Fire latency buckets (seconds) around the 5 ms p99 goal.
_BUCKETS = (0.0005, 0.001, 0.002, 0.003, 0.005, 0.0075, 0.01, 0.025, 0.05, 0.1, 0.25, 1.0, 2.5)


class Metrics:
    """The counters and histograms the routes update."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry(auto_describe=True)
        self.fires = Counter(
            "printeps_fires", "Fire requests answered, by rule set and outcome (ok/error).",
            ["ruleset", "outcome"], registry=self.registry,
        )
        self.fire_seconds = Histogram(
            "printeps_fire_seconds", "Time to answer a fire request (engine call incl. conversion).",
            ["ruleset"], buckets=_BUCKETS, registry=self.registry,
        )
        self.rules_fired = Counter(
            "printeps_rules_fired", "Rule activations fired, by rule set.", ["ruleset"], registry=self.registry,
        )
        self.deploys = Counter(
            "printeps_deploys", "Rule set changes, by kind (deploy/rollback/delete).",
            ["ruleset", "kind"], registry=self.registry,
        )
        self.errors = Counter(
            "printeps_errors", "Error answers, by kind (HTTP status or engine error type).",
            ["kind"], registry=self.registry,
        )
        self.refused = Counter(
            "printeps_fires_refused", "Fires refused before they started because their rule set was overloaded, by "
            "reason (queue_full: 429, api.max_queue; waited: 503, api.max_wait_s).",
            ["ruleset", "reason"], registry=self.registry,
        )
        self.timeouts = Counter(
            "printeps_fire_timeouts", "Fires halted after engine.fire_timeout_s (answered 503, nothing recorded).",
            ["ruleset"], registry=self.registry,
        )
        self.rulesets = Gauge("printeps_rulesets", "Rule sets currently deployed.", registry=self.registry)

    def watch_bulkheads(self, stats: Callable[[], dict[str, dict[str, Any]]], max_queue: int) -> None:
        """Export each rule set's bulkhead queue (:mod:`gateway.engine.bulkhead`), read at scrape time."""
        self.registry.register(BulkheadCollector(stats, max_queue))

    def observe_fire(self, ruleset: str, seconds: float, fired: int) -> None:
        self.fires.labels(ruleset, "ok").inc()
        self.fire_seconds.labels(ruleset).observe(seconds)
        if fired:
            self.rules_fired.labels(ruleset).inc(fired)

    def fire_failed(self, ruleset: str) -> None:
        self.fires.labels(ruleset, "error").inc()

    def fire_error(self, ruleset: str, exc: BaseException) -> None:
        """Counts a fire that did not answer: refused (overloaded), halted (timeout) or failed."""
        if isinstance(exc, Overloaded):
            self.refused.labels(ruleset, exc.reason).inc()
            return
        if isinstance(exc, FireTimeout):
            self.timeouts.labels(ruleset).inc()
        self.fire_failed(ruleset)

    def on_engine_event(self, kind: str, payload: dict[str, Any]) -> None:
        """Engine listener: count deploys/rollbacks/deletes."""
        if kind in ("deploy", "rollback", "delete"):
            self.deploys.labels(str(payload.get("name") or payload.get("ruleset") or "?"), kind).inc()

    def render(self) -> bytes:
        return generate_latest(self.registry)


class BulkheadCollector(Collector):
    """The queue depth of each rule set's bulkhead, read when ``/metrics`` is scraped.

    Why gauges read at scrape time rather than updated by the routes: the depth changes on the
    workers' threads at every hand-off; reading the bulkheads' own counters when asked costs the hot
    path nothing and is never stale. ``printeps_fire_queue_depth`` is what an operator alerts on
    (near ``printeps_fire_queue_limit``, fires start being refused with 429)."""

    def __init__(self, stats: Callable[[], dict[str, dict[str, Any]]], max_queue: int) -> None:
        self._stats = stats
        self._max_queue = max_queue

    def collect(self) -> Iterator[GaugeMetricFamily]:
        depth = GaugeMetricFamily("printeps_fire_queue_depth", "Fires waiting in the rule set's bulkhead queue "
                                  "(refused with 429 at printeps_fire_queue_limit, api.max_queue).", labels=["ruleset"])
        running = GaugeMetricFamily("printeps_fires_running", "Fires of the rule set running on its bulkhead's "
                                    "threads (at most api.fire_workers).", labels=["ruleset"])
        for name, stats in sorted(self._stats().items()):
            depth.add_metric([name], stats["waiting"])
            running.add_metric([name], stats["running"])
        yield depth
        yield running
        yield GaugeMetricFamily("printeps_fire_queue_limit", "The most fires a rule set's queue holds (api.max_queue).",
                                value=self._max_queue)
