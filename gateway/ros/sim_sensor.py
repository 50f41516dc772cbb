"""A Kinect-like entrance sensor as a real ROS node: replays a scenario file on the entrance topic.

Publishes printeps_interfaces/Entrance on ``entrance`` (and EntranceSensor on ``entrance_sensor``
with --sensor-topic) at the scenario's rate (``rate_hz`` overrides it). ``speed`` > 1 replays faster
than real time: the stamps follow scenario time, so the detection windows see the same data.

    python -m gateway.ros.sim_sensor scenarios/teahouse-reception.yaml [--rate 2] [--speed 1]
"""

from __future__ import annotations

from typing import Any

from gateway.ros.convert import dict_to_entrance
from gateway.ros.replay import ScenarioReplayNode, play, replay_arguments
from gateway.ros.scenario import Scenario, load_scenario

from printeps_interfaces.msg import Entrance, EntranceSensor


class EntranceSensorSim(ScenarioReplayNode):
    """Replays ``scenario`` once in a thread (start()); ``done`` is set when the last reading is out."""

    def __init__(self, scenario: Scenario, *, topic: str = "entrance", sensor_topic: str | None = None,
                 **replay: Any) -> None:
        super().__init__(f"{scenario.sensor_id}_sim", scenario, **replay)
        self.pub = self.create_publisher(Entrance, topic, 100)
        self.sensor_pub = self.create_publisher(EntranceSensor, sensor_topic, 100) if sensor_topic else None

    def subscribed(self) -> bool:
        return self.pub.get_subscription_count() > 0

    def publish_reading(self, reading: dict[str, Any]) -> None:
        msg = dict_to_entrance(reading)
        self.pub.publish(msg)
        if self.sensor_pub:
            self.sensor_pub.publish(EntranceSensor(sensor_id=self.scenario.sensor_id, location=self.scenario.location,
                                                   distance_to_entrance=self.scenario.distance_to_entrance,
                                                   entrance=msg))


def main(argv: list[str] | None = None) -> int:
    ap = replay_arguments(__doc__.splitlines()[0], "entrance")
    ap.add_argument("--sensor-topic", default=None)
    args = ap.parse_args(argv)
    scenario = load_scenario(args.scenario)
    return play("sensor simulator", scenario,
                lambda rt: rt.make(EntranceSensorSim, scenario, topic=args.topic, sensor_topic=args.sensor_topic,
                                   rate_hz=args.rate, speed=args.speed))


if __name__ == "__main__":
    raise SystemExit(main())
