"""Where the time of the ROS path goes: bench/ros_latency.py with every hop timed.

Why: the reading → Speak latency is one number; when it moves, this says which hop moved. Each hop
of the path (ROS callback → ingress queue → mapping → stream push → window → binding fire → rules
→ decision record → ``actions`` event → action router → robot service calls → Speak at the robot)
is wrapped to note when it starts and ends and on which thread. Per trial, the offsets are taken
from the publish of the reading that completed the detection (the last one before the Speak); the
table gives their medians over the trials. Works on any tree of the gateway (hops a tree lacks are
left out), so two trees can be compared hop by hop:

    PYTHONPATH=<tree> .venv/bin/python bench/ros_hops.py [trials=60]
"""

from __future__ import annotations

import functools
import importlib
import json
import os
import statistics
import sys
import threading
import time
from collections import defaultdict
from typing import Any, Callable

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

EVENTS: list[tuple[str, float, float, str]] = []  # (label, start, end, thread)
_LOCK = threading.Lock()

# (module, class, method, label); a label may name the call's argument via a function below
HOPS: list[tuple[str, str | None, str, str]] = [
    ("gateway.ros.ingress", "Ingress", "enqueue", "ros callback → ingress queue"),
    ("gateway.ros.ingress", "Ingress", "handle", "ingress: check, map, push, record"),
    ("gateway.rdf.mapping", "Mapper", "map", "mapping → RDF"),
    ("gateway.stream.engine", "StreamEngine", "push", "stream push"),
    ("gateway.stream.scheduler", "Scheduler", "instant", "window evaluated (under the lock)"),
    ("gateway.stream.engine", "StreamEngine", "_instant", "window evaluated (under the lock)"),
    ("gateway.stream.subscriber", "BindingSubscriber", "deliver", "deliver (after the lock)"),
    ("gateway.stream.binding_fire", "BindingFirer", "fire", "binding hand-off + wait"),
    ("gateway.stream.subscriber", "BindingSubscriber", "_fire", "binding fire (binding thread)"),
    ("gateway.stream.engine", "StreamEngine", "_fire_binding", "binding fire (binding thread)"),
    ("gateway.engine.engine", "Engine", "fire", "engine.fire"),
    ("gateway.engine.recorder", "DecisionRecorder", "record", "decision recorded"),
    ("gateway.engine.engine", "Engine", "record_decision", "decision recorded"),
    ("gateway.runtime.actions", "ActionRouter", "on_stream_event", "actions event → router queue"),
    ("gateway.runtime.actions", "ActionRouter", "perform", "action performed"),
    ("gateway.ros.node", "RosServiceCaller", "call", "robot service call"),
    ("gateway.ros.sim_robot", "RobotSim", "_move", "robot: MoveTo served"),
    ("gateway.ros.sim_robot", "RobotSim", "_speak", "robot: Speak served"),
    ("gateway.store.store", "InformationState", "record_many", "store.record"),
    # inside the window evaluation
    ("gateway.stream.evaluator", "Evaluator", "evaluate", "  SPARQL evaluation"),
    ("gateway.stream.engine", "StreamEngine", "_run", "  SPARQL evaluation"),
    ("gateway.stream.engine", "StreamEngine", "_publish", "  stream event to subscribers"),
    ("gateway.stream.subscriber", "BindingSubscriber", "prepare", "  binding facts prepared"),
    ("gateway.stream.engine", None, "binding_facts", "  binding facts prepared"),
    ("gateway.runtime.live", "LiveFeed", "on_stream_event", "  live feed: stream event"),
    ("gateway.runtime.live", "LiveFeed", "on_engine_event", "  live feed: decision"),
]


def _wrap(fn: Callable[..., Any], label: str, keep: Callable[..., bool] | None = None) -> Callable[..., Any]:
    @functools.wraps(fn)
    def traced(*args: Any, **kwargs: Any) -> Any:
        if keep is not None and not keep(*args, **kwargs):
            return fn(*args, **kwargs)
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            end = time.perf_counter()
            with _LOCK:
                EVENTS.append((label, start, end, threading.current_thread().name))
    return traced


def install() -> list[str]:
    """Wrap every hop this tree has; returns the labels wrapped."""
    done = []
    for module, cls, method, label in HOPS:
        try:
            owner = getattr(importlib.import_module(module), cls) if cls else importlib.import_module(module)
        except (ImportError, AttributeError):
            continue
        fn = owner.__dict__.get(method)
        if fn is None:
            continue
        setattr(owner, method, _wrap(fn, label))
        done.append(label)
    from rclpy.publisher import Publisher

    Publisher.publish = _wrap(Publisher.publish, "entrance reading published",
                              keep=lambda self, *a, **k: self.topic_name.endswith("/entrance"))
    return done


CHAIN = [  # (point, label, which end, searched from): each point the first such event after the
    # start of the point it is searched from (the one before it unless named)
    ("ROS callback", "ros callback → ingress queue", 0, None),
    ("ingress picks it up", "ingress: check, map, push, record", 0, None),
    ("stream push", "stream push", 0, None),
    ("window evaluation starts", "window evaluated (under the lock)", 0, None),
    ("window evaluation ends", "window evaluated (under the lock)", 1, "window evaluation starts"),
    ("binding fire starts", "binding fire (binding thread)", 0, "window evaluation starts"),
    ("binding fire ends", "binding fire (binding thread)", 1, "binding fire starts"),
    ("actions event queued", "actions event → router queue", 0, "binding fire starts"),
    ("first action starts (MoveTo)", "action performed", 0, "binding fire starts"),
    ("MoveTo served at the robot", "robot: MoveTo served", 0, None),
    ("MoveTo call returns", "robot service call", 1, "first action starts (MoveTo)"),
    ("Speak served at the robot", "robot: Speak served", 0, None),
]


def _first(events: list[tuple[str, float, float, str]], label: str, after: float) -> tuple[str, float, float, str] | None:
    return next((e for e in events if e[0] == label and e[1] >= after), None)


def _breakdown(events: list[tuple[str, float, float, str]], speaks: list[tuple[str, float, float, str]],
               publishes: list[float], warm: int) -> None:
    """Per trial, the time of each labelled call between the reading's publish and the Speak,
    summed by label (indented labels are parts of the window evaluation); medians over trials."""
    sums: dict[str, list[float]] = defaultdict(list)
    counted = 0
    for n, speak in enumerate(speaks):
        before = [t for t in publishes if t < speak[1]]
        if n < warm or not before:
            continue
        counted += 1
        per: dict[str, float] = defaultdict(float)
        for label, start, end, _thread in events:
            if before[-1] <= start <= speak[1] and label.startswith("  "):
                per[label] += (end - start) * 1000
        for label, total in per.items():
            sums[label].append(total)
    for label, xs in sorted(sums.items()):
        xs = xs + [0.0] * (counted - len(xs))
        print(f"{label:<40} total per trial: median {statistics.median(xs):6.2f} ms")


def report(events: list[tuple[str, float, float, str]] | None = None, warm: int = 10) -> None:
    """Per trial (the Speak at the robot and the last reading published before it), the offset of
    each point of :data:`CHAIN` from that publish; the table gives their medians and the median of
    each step (a point's offset minus the previous point's, per trial)."""
    events = sorted(EVENTS if events is None else [tuple(e) for e in events], key=lambda e: e[1])
    speaks = [e for e in events if e[0] == "robot: Speak served"]
    publishes = [e[1] for e in events if e[0] == "entrance reading published"]
    offsets: dict[str, list[float]] = defaultdict(list)
    steps: dict[str, list[float]] = defaultdict(list)
    for n, speak in enumerate(speaks):
        before = [t for t in publishes if t < speak[1]]
        if n < warm or not before:
            continue
        t0 = before[-1]
        window = [e for e in events if t0 <= e[1] <= speak[2]]
        starts: dict[str, float] = {}
        points: list[tuple[str, float]] = []
        for point, label, end, anchor in CHAIN:
            after = starts[anchor] if anchor else (starts[points[-1][0]] if points else t0)
            found = speak if label == "robot: Speak served" else _first(window, label, after)
            if found is None:
                break
            starts[point] = found[1]
            points.append((point, (found[1 + end] - t0) * 1000))
        else:
            previous = 0.0
            for point, offset in points:
                offsets[point].append(offset)
                steps[point].append(offset - previous)
                previous = offset
    _breakdown(events, speaks, publishes, warm)
    trials = len(offsets["Speak served at the robot"])
    print(f"trials with the whole chain: {trials}")
    print(f"{'point':<34} {'offset median ms':>17} {'step median ms':>15} {'step p90 ms':>12}")
    for point, _label, _end, _anchor in CHAIN:
        xs = steps[point]
        if xs:
            print(f"{point:<34} {statistics.median(offsets[point]):17.2f} {statistics.median(xs):15.2f} "
                  f"{sorted(xs)[int(0.9 * (len(xs) - 1))]:12.2f}")


def main() -> int:
    if sys.argv[1:2] == ["--report"]:  # read a dump (ROS_HOPS_DUMP) again
        for path in sys.argv[2:]:
            print(path)
            with open(path) as dump:
                report(json.load(dump))
        return 0
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    labels = install()
    print("traced:", ", ".join(dict.fromkeys(labels)))
    import ros_latency

    ros_latency.main()
    if os.environ.get("ROS_HOPS_DUMP"):  # the raw events, to read again with report(events)
        with open(os.environ["ROS_HOPS_DUMP"], "w") as out:
            json.dump(EVENTS, out)
    report()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
