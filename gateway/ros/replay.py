"""What every simulated sensor node shares: replaying a scenario's readings on time, and its main.

A scenario (gateway.ros.scenario) yields readings with their offset ``t`` in scenario seconds; a
sensor node publishes each as its message type. The timing, the wait for a subscriber, stopping and
the command line (``--rate``, ``--speed``, signals, the ROS runtime) are the same for every sensor,
so they live here once; a sensor says only how a reading becomes messages (:meth:`publish_reading`).
"""

from __future__ import annotations

import argparse
import signal
import threading
import time
from typing import Any, Callable

from rclpy.node import Node


class ScenarioReplayNode(Node):
    """Replays ``scenario`` once in a thread (start()); ``done`` is set when the last reading is out.

    ``speed`` > 1 replays faster than real time; the readings' stamps follow scenario time, so the
    detection windows see the same data at any speed."""

    def __init__(self, node_name: str, scenario: Any, *, rate_hz: float | None = None, speed: float = 1.0,
                 wait_for_subscribers: float = 10.0, on_reading: Callable[[dict[str, Any]], None] | None = None,
                 context: Any = None) -> None:
        super().__init__(node_name, context=context)
        self.scenario = scenario
        self.rate_hz = rate_hz or scenario.rate_hz
        self.speed = speed
        self.wait_for_subscribers = wait_for_subscribers
        self.on_reading = on_reading
        self.published = 0
        self.done = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"{node_name}-replay", daemon=True)

    def publish_reading(self, reading: dict[str, Any]) -> None:
        """Publish one reading (the sensor's message types)."""
        raise NotImplementedError

    def subscribed(self) -> bool:
        """Someone listens on the main topic (the replay waits for that, up to ``wait_for_subscribers``)."""
        raise NotImplementedError

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)

    def _run(self) -> None:
        deadline = time.monotonic() + self.wait_for_subscribers
        while not self.subscribed() and time.monotonic() < deadline and not self._stop.is_set():
            time.sleep(0.05)
        time.sleep(0.2)  # let the matched subscriber finish its side of discovery
        t0_wall = time.monotonic()
        for reading in self.scenario.readings(start=time.time(), rate_hz=self.rate_hz):
            due = t0_wall + reading["t"] / self.speed
            while not self._stop.is_set() and time.monotonic() < due:
                time.sleep(min(0.05, max(0.0, due - time.monotonic())))
            if self._stop.is_set():
                break
            self.publish_reading(reading)
            self.published += 1
            if self.on_reading:
                self.on_reading(reading)
        self.done.set()


def replay_arguments(description: str, topic: str) -> argparse.ArgumentParser:
    """The command line every sensor simulator accepts (a sensor may add its own options)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("scenario")
    ap.add_argument("--rate", type=float, default=None, help="readings per second (default: the scenario's)")
    ap.add_argument("--speed", type=float, default=1.0, help="replay speed factor")
    ap.add_argument("--topic", default=topic)
    return ap


def play(label: str, scenario: Any, make: Callable[[Any], ScenarioReplayNode]) -> int:
    """Run one sensor node (``make(runtime)``) until its scenario is played or SIGINT/SIGTERM."""
    from gateway.ros.runtime import RosRuntime

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    rt = RosRuntime()
    try:
        sim = make(rt)
        sim.start()
        print(f"{label}: playing {scenario.name!r} ({scenario.duration:.0f} s)", flush=True)
        while not stop.is_set() and not sim.done.is_set():
            stop.wait(0.1)
        print(f"{label}: published {sim.published} readings", flush=True)
    finally:
        rt.shutdown()
    return 0
