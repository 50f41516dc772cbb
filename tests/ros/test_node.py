"""The gateway node with real rclpy nodes over loopback, a real engine and a real store."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from gateway.ros.convert import dict_to_entrance
from gateway.ros.node import GatewayNode
from gateway.ros.runtime import RosRuntime
from gateway.ros.scenario import load_scenario
from gateway.ros.sim_robot import RobotSim
from gateway.ros.sim_sensor import EntranceSensorSim
from gateway.ros.stages import pipeline_factory

from ros_helpers import wait_for

pytestmark = pytest.mark.ros
SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "teahouse-reception.yaml"


def start_gateway(rt: RosRuntime, settings, store, rules) -> GatewayNode:
    return rt.make(GatewayNode, settings.ros, pipeline_factory(settings, store, rules), rules=rules, store=store)


def test_scenario_reaches_the_robot_in_order_and_everything_is_recorded(domain_id, settings, store,
                                                                        engine_rules) -> None:
    with RosRuntime(domain_id=domain_id) as rt:
        robot = rt.make(RobotSim, "pepper")
        gw = start_gateway(rt, settings, store, engine_rules)
        sensor = rt.make(EntranceSensorSim, load_scenario(SCENARIO), speed=4.0)
        sensor.start()
        assert sensor.done.wait(30)
        assert wait_for(lambda: gw.queue.empty() and len(robot.calls) >= 8, 20), robot.calls
        wait_for(lambda: False, 0.5)
    said = [c["text"] for c in robot.calls if c["service"] == "speak"]
    assert said == ["Welcome. Two seats?", "Welcome. Three seats?"]
    seq = [(c["service"], c.get("location") or c.get("text") or c.get("name")) for c in robot.calls]
    first = seq[: seq.index(("speak", "Welcome. Three seats?"))]
    assert first[0] == ("move_to", "entrance") and ("speak", "Welcome. Two seats?") in first
    assert first.index(("speak", "Welcome. Two seats?")) < first.index(("move_to", "table for two"))
    rest = seq[len(first) - 1:]
    assert rest[0] == ("move_to", "entrance") and rest[-1] == ("move_to", "table for four")
    # the Information State holds every step
    assert store.count("sensor_messages") == sensor.published
    assert store.count("rdf_events") == sensor.published
    assert store.count("query_results") >= 5
    firings = store.query("rule_firings", newest_first=False)
    assert len(firings) == 2 and firings[0]["version"] >= 1 and firings[0]["facts"][0]["type"] == "Entrance"
    assert store.count("actions") == len(robot.calls)
    assert {d["status"] for d in store.query("actions", limit=100)} == {"ok"}


def test_bad_sensor_values_are_rejected_recorded_and_do_not_stop_the_node(domain_id, settings, store,
                                                                          engine_rules) -> None:
    with RosRuntime(domain_id=domain_id) as rt:
        gw = start_gateway(rt, settings, store, engine_rules)
        from rclpy.node import Node
        from printeps_interfaces.msg import Entrance
        pub_node = rt.make(Node, "bad_sensor")
        pub = pub_node.create_publisher(Entrance, "entrance", 100)
        assert wait_for(lambda: pub.get_subscription_count() > 0, 15)
        wait_for(lambda: False, 0.3)
        bad = [
            {"id": "neg", "customers": [{"id": "a", "distance": -1.0}], "stamp": 1.0},
            {"id": "nan", "customers": [{"id": "a", "distance": math.nan}], "stamp": 2.0},
            {"id": "many", "customers": [{"id": f"c{i}", "distance": 2.0} for i in range(1000)], "stamp": 3.0},
            {"id": "ok", "customers": [{"id": "a", "distance": 2.0}], "stamp": 4.0},
        ]
        for b in bad:
            pub.publish(dict_to_entrance(b))
        assert wait_for(lambda: store.count("sensor_messages") == 4, 15)
        assert gw.pipeline.stats["rejected"] == 3 and gw.pipeline.stats["readings"] == 1
    rejected = {d["reading"]["id"]: d["error"]["field"]
                for d in store.query("sensor_messages", type="printeps/RejectedEntrance")}
    assert rejected == {"neg": "customers[0].distance", "nan": "customers[0].distance",
                        "many": "number_of_customers"}


def _one_group(customers=("a", "b")):
    """Readings that complete a detection of a pair walking up (1 Hz, like the papers)."""
    return [{"id": f"e{i}", "stamp": 1000.0 + i,
             "customers": [{"id": c, "distance": d, "age": 30, "gender": "female"} for c in customers]}
            for i, d in enumerate([5.0, 4.0, 3.0, 2.0, 1.8])]


def test_missing_robot_service_is_retried_then_recorded(domain_id, settings, store, engine_rules) -> None:
    settings.ros.robots = {"pepper": "/nobody_here"}
    settings.ros.call_timeout_s = 0.3
    with RosRuntime(domain_id=domain_id) as rt:
        gw = start_gateway(rt, settings, store, engine_rules)
        outcomes = [o for r in _one_group() for o in gw.pipeline.on_reading(r)]
    assert outcomes and {o["status"] for o in outcomes} == {"no_service"}
    assert all(o["attempts"] == 2 for o in outcomes)
    assert store.count("actions", **{"_meta.stored_type": "printeps/Action/no_service"}) == len(outcomes)


def test_hanging_robot_times_out_then_recorded(domain_id, settings, store, engine_rules) -> None:
    settings.ros.call_timeout_s = 0.4
    settings.ros.call_retries = 1
    with RosRuntime(domain_id=domain_id) as robot_rt, RosRuntime(domain_id=domain_id) as rt:
        robot_rt.make(RobotSim, "pepper", hang_s=1.5)
        gw = start_gateway(rt, settings, store, engine_rules)
        assert wait_for(lambda: gw.caller.client("/pepper/speak", "Speak").service_is_ready(), 15)
        reading = _one_group()
        outcomes = [o for r in reading for o in gw.pipeline.on_reading(r)]
    assert outcomes and outcomes[0]["status"] == "timeout" and outcomes[0]["attempts"] == 2
    assert "did not answer within 0.4 s" in outcomes[0]["message"]
    assert store.count("actions", **{"_meta.stored_type": "printeps/Action/timeout"}) >= 1


def test_fire_business_rules_service(domain_id, settings, store, engine_rules) -> None:
    from rclpy.node import Node
    from printeps_interfaces.srv import FireBusinessRules

    facts = [{"type": "Entrance", "id": "entrance", "number_of_customers": 1},
             {"type": "Customer", "id": "a", "entrance": "entrance", "age": 30, "gender": "male", "distance": 2.0},
             {"type": "Robot", "id": "pepper", "position": "entrance"}]
    with RosRuntime(domain_id=domain_id) as rt:
        start_gateway(rt, settings, store, engine_rules)
        client = rt.make(Node, "workflow").create_client(FireBusinessRules, "fire_business_rules")
        assert client.wait_for_service(timeout_sec=15)
        res = client.call(FireBusinessRules.Request(ruleset="reception", facts_json=json.dumps(facts)), timeout_sec=10)
        assert res.success and res.version >= 1
        assert any(a["params"].get("text", "").startswith("Welcome.") for a in json.loads(res.actions_json))
        bad = client.call(FireBusinessRules.Request(ruleset="reception", facts_json='[{"type": '), timeout_sec=10)
        assert not bad.success and json.loads(bad.error)["column"] > 1
        missing = client.call(FireBusinessRules.Request(ruleset="nope", facts_json="[]"), timeout_sec=10)
        assert not missing.success and "nope" in missing.error


def test_gateway_restart_mid_scenario_loses_nothing(domain_id, settings, store, engine_rules) -> None:
    scenario = load_scenario(SCENARIO)
    readings = list(scenario.readings(start=5000.0))
    half = len(readings) // 2
    calls = []
    with RosRuntime(domain_id=domain_id) as robot_rt:
        robot = robot_rt.make(RobotSim, "pepper", on_call=calls.append)
        for part in (readings[:half], readings[half:]):  # the gateway is stopped and started in between
            with RosRuntime(domain_id=domain_id) as rt:
                gw = start_gateway(rt, settings, store, engine_rules)
                assert wait_for(lambda: gw.caller.client("/pepper/speak", "Speak").service_is_ready(), 15)
                for r in part:
                    gw.pipeline.on_reading(dict(r))
        assert robot is not None
    assert store.count("sensor_messages") == len(readings)
    assert [c["text"] for c in calls if c["service"] == "speak"] == ["Welcome. Two seats?", "Welcome. Three seats?"]
