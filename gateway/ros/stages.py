"""Wire the real pipeline stages: detector (stream side), rules (gateway.engine), dispatcher, store.

Why one place: the node, the demo and the benchmark all build the same chain; tests replace single
stages by passing their own.
"""

from __future__ import annotations

import logging
from typing import Any, Callable

from gateway.ros.detector import EntryDetector, EventDetector
from gateway.ros.dispatcher import ActionDispatcher
from gateway.ros.pipeline import Pipeline, Rules, engine_rules

log = logging.getLogger(__name__)


def make_detector(settings: Any) -> EventDetector:
    """The entry detector: gateway.stream's C-SPARQL engine when available, else the plain-Python one."""
    try:
        from gateway.ros.stream_detector import stream_detector

        return stream_detector(settings)
    except ImportError as exc:  # the stream package is optional for the ROS side
        log.warning("gateway.stream not available (%s): using the built-in entry detector", exc)
        return EntryDetector()


def pipeline_factory(settings: Any, store: Any, rules: Rules, *, detector: EventDetector | None = None,
                     on_event: Callable[[str, dict[str, Any]], None] | None = None,
                     on_outcome: Callable[[dict[str, Any]], None] | None = None) -> Callable[[Any], Pipeline]:
    """A factory for GatewayNode: builds the Pipeline once the node (and its service caller) exists."""
    ros = settings.ros

    def build(node: Any) -> Pipeline:
        dispatcher = ActionDispatcher(node.caller, dict(ros.robots), timeout_s=ros.call_timeout_s,
                                      retries=ros.call_retries, store=store, on_outcome=on_outcome)
        return Pipeline(detector or make_detector(settings), rules, dispatcher, store, ruleset=ros.ruleset,
                        robot_positions=dict(ros.robot_start), max_customers=ros.max_customers,
                        max_distance_m=ros.max_distance_m, on_event=on_event)

    return build


def engine_stage(settings: Any) -> tuple[Any, Rules]:
    """Start the engine with the rule sets from the rules dir; returns (engine, rules stage)."""
    from gateway import jvm
    from gateway.engine import Engine

    jvm.start(settings.jvm)  # from this (the main) thread; jvm.start adds -Xrs for a clean ROS exit
    engine = Engine(settings)
    engine.load_rules_dir()
    rules = engine_rules(engine)
    engine.warm_up(rounds=0, fires=20, background=False)  # the first customer must not pay for the JIT
    return engine, rules
