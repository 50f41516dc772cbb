"""Table sensors as a real ROS node: replays a tables scenario on the ``teahouse_objects`` topic.

Publishes printeps_interfaces/TeahouseObject — each table (every sensor reports its own table, so
the leaving-seat detector's clock moves) and everyone seated at it — at the scenario's rate.
``speed`` > 1 replays faster than real time: the stamps follow scenario time.

    python -m gateway.ros.sim_tables scenarios/teahouse-tables.yaml [--rate 2] [--speed 1]
"""

from __future__ import annotations

from typing import Any

from gateway.ros.convert import float_to_stamp
from gateway.ros.replay import ScenarioReplayNode, play, replay_arguments
from gateway.ros.scenario import TableScenario, load_scenario

from printeps_interfaces.msg import TeahouseObject


class TableSensorSim(ScenarioReplayNode):
    """Replays ``scenario`` once in a thread (start()); ``done`` is set when the last reading is out."""

    def __init__(self, scenario: TableScenario, *, topic: str = "teahouse_objects", **replay: Any) -> None:
        super().__init__("table_sensors_sim", scenario, **replay)
        self.pub = self.create_publisher(TeahouseObject, topic, 100)

    def subscribed(self) -> bool:
        return self.pub.get_subscription_count() > 0

    def publish_reading(self, reading: dict[str, Any]) -> None:
        self.pub.publish(TeahouseObject(id=reading["id"], type=reading["type"], location=reading["location"],
                                        x=float(reading["x"]), y=float(reading["y"]),
                                        distance=float(reading["distance"]), stamp=float_to_stamp(reading["stamp"])))


def main(argv: list[str] | None = None) -> int:
    args = replay_arguments(__doc__.splitlines()[0], "teahouse_objects").parse_args(argv)
    scenario = load_scenario(args.scenario, TableScenario)
    return play("table sensors", scenario,
                lambda rt: rt.make(TableSensorSim, scenario, topic=args.topic, rate_hz=args.rate, speed=args.speed))


if __name__ == "__main__":
    raise SystemExit(main())
