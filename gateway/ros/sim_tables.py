"""Table sensors as a real ROS node: replays a tables scenario on the ``teahouse_objects`` topic.

Publishes printeps_interfaces/TeahouseObject — each table (every sensor reports its own table, so
the leaving-seat detector's clock moves) and everyone seated at it — at the scenario's rate.
``speed`` > 1 replays faster than real time: the stamps follow scenario time.

    python -m gateway.ros.sim_tables scenarios/teahouse-tables.yaml [--rate 2] [--speed 1]
"""

from __future__ import annotations

import argparse
import signal
import threading
import time
from typing import Any, Callable

from rclpy.node import Node

from gateway.ros.convert import float_to_stamp
from gateway.ros.scenario import TableScenario, load_scenario

from printeps_interfaces.msg import TeahouseObject


class TableSensorSim(Node):
    """Replays ``scenario`` once in a thread (start()); ``done`` is set when the last reading is out."""

    def __init__(self, scenario: TableScenario, *, topic: str = "teahouse_objects", rate_hz: float | None = None,
                 speed: float = 1.0, wait_for_subscribers: float = 10.0,
                 on_reading: Callable[[dict[str, Any]], None] | None = None, context: Any = None) -> None:
        super().__init__("table_sensors_sim", context=context)
        self.scenario = scenario
        self.rate_hz = rate_hz or scenario.rate_hz
        self.speed = speed
        self.wait_for_subscribers = wait_for_subscribers
        self.on_reading = on_reading
        self.pub = self.create_publisher(TeahouseObject, topic, 100)
        self.published = 0
        self.done = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="tables-sim", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout=5.0)

    def _run(self) -> None:
        deadline = time.monotonic() + self.wait_for_subscribers
        while self.pub.get_subscription_count() < 1 and time.monotonic() < deadline and not self._stop.is_set():
            time.sleep(0.05)
        time.sleep(0.2)  # let the matched subscriber finish its side of discovery
        t0_wall = time.monotonic()
        for reading in self.scenario.readings(start=time.time(), rate_hz=self.rate_hz):
            due = t0_wall + reading["t"] / self.speed
            while not self._stop.is_set() and time.monotonic() < due:
                time.sleep(min(0.05, max(0.0, due - time.monotonic())))
            if self._stop.is_set():
                break
            self.pub.publish(TeahouseObject(id=reading["id"], type=reading["type"], location=reading["location"],
                                            x=float(reading["x"]), y=float(reading["y"]),
                                            distance=float(reading["distance"]), stamp=float_to_stamp(reading["stamp"])))
            self.published += 1
            if self.on_reading:
                self.on_reading(reading)
        self.done.set()


def main(argv: list[str] | None = None) -> int:
    from gateway.ros.runtime import RosRuntime

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario")
    ap.add_argument("--rate", type=float, default=None, help="readings per second per object (default: the scenario's)")
    ap.add_argument("--speed", type=float, default=1.0, help="replay speed factor")
    ap.add_argument("--topic", default="teahouse_objects")
    args = ap.parse_args(argv)
    scenario = load_scenario(args.scenario, TableScenario)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    rt = RosRuntime()
    try:
        sim = rt.make(TableSensorSim, scenario, topic=args.topic, rate_hz=args.rate, speed=args.speed)
        sim.start()
        print(f"table sensors: playing {scenario.name!r} ({scenario.duration:.0f} s)", flush=True)
        while not stop.is_set() and not sim.done.is_set():
            stop.wait(0.1)
        print(f"table sensors: published {sim.published} readings", flush=True)
    finally:
        rt.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
