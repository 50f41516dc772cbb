"""A Kinect-like entrance sensor as a real ROS node: replays a scenario file on the entrance topic.

Publishes printeps_interfaces/Entrance on ``entrance`` (and EntranceSensor on ``entrance_sensor``
with --sensor-topic) at the scenario's rate (``rate_hz`` overrides it). ``speed`` > 1 replays faster
than real time: the stamps follow scenario time, so the detection windows see the same data.

    python -m gateway.ros.sim_sensor scenarios/teahouse-reception.yaml [--rate 2] [--speed 1]
"""

from __future__ import annotations

import argparse
import signal
import threading
import time
from typing import Any, Callable

from rclpy.node import Node

from gateway.ros.convert import dict_to_entrance
from gateway.ros.scenario import Scenario, load_scenario

from printeps_interfaces.msg import Entrance, EntranceSensor


class EntranceSensorSim(Node):
    """Replays ``scenario`` once in a thread (start()); ``done`` is set when the last reading is out."""

    def __init__(self, scenario: Scenario, *, topic: str = "entrance", sensor_topic: str | None = None,
                 rate_hz: float | None = None, speed: float = 1.0, wait_for_subscribers: float = 10.0,
                 on_reading: Callable[[dict[str, Any]], None] | None = None, context: Any = None) -> None:
        super().__init__(f"{scenario.sensor_id}_sim", context=context)
        self.scenario = scenario
        self.rate_hz = rate_hz or scenario.rate_hz
        self.speed = speed
        self.wait_for_subscribers = wait_for_subscribers
        self.on_reading = on_reading
        self.pub = self.create_publisher(Entrance, topic, 100)
        self.sensor_pub = self.create_publisher(EntranceSensor, sensor_topic, 100) if sensor_topic else None
        self.published = 0
        self.done = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sensor-sim", daemon=True)

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
        start = time.time()
        for reading in self.scenario.readings(start=start, rate_hz=self.rate_hz):
            due = t0_wall + reading["t"] / self.speed
            while not self._stop.is_set() and time.monotonic() < due:
                time.sleep(min(0.05, max(0.0, due - time.monotonic())))
            if self._stop.is_set():
                break
            msg = dict_to_entrance(reading)
            self.pub.publish(msg)
            if self.sensor_pub:
                self.sensor_pub.publish(EntranceSensor(sensor_id=self.scenario.sensor_id, location=self.scenario.location,
                                                       distance_to_entrance=self.scenario.distance_to_entrance,
                                                       entrance=msg))
            self.published += 1
            if self.on_reading:
                self.on_reading(reading)
        self.done.set()


def main(argv: list[str] | None = None) -> int:
    from gateway.ros.runtime import RosRuntime

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario")
    ap.add_argument("--rate", type=float, default=None, help="readings per second (default: the scenario's)")
    ap.add_argument("--speed", type=float, default=1.0, help="replay speed factor")
    ap.add_argument("--topic", default="entrance")
    ap.add_argument("--sensor-topic", default=None)
    args = ap.parse_args(argv)
    scenario = load_scenario(args.scenario)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    rt = RosRuntime()
    try:
        sim = rt.make(EntranceSensorSim, scenario, topic=args.topic, sensor_topic=args.sensor_topic,
                      rate_hz=args.rate, speed=args.speed)
        sim.start()
        print(f"sensor simulator: playing {scenario.name!r} ({scenario.duration:.0f} s)", flush=True)
        while not stop.is_set() and not sim.done.is_set():
            stop.wait(0.1)
        print(f"sensor simulator: published {sim.published} readings", flush=True)
    finally:
        rt.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
