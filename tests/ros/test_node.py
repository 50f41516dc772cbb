"""The gateway's ROS node, built by the one composition root, with real rclpy nodes over loopback,
a real engine and a real Information State: topic → RDF → window → binding → rules → robot."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (ros/install.sh)")
pytest.importorskip("printeps_interfaces", reason="printeps_interfaces not built (ros/install.sh)")

from gateway.ros.convert import dict_to_entrance, to_dict
from gateway.ros.runtime import RosRuntime
from gateway.ros.scenario import load_scenario
from gateway.ros.sim_robot import RobotSim
from gateway.ros.sim_sensor import EntranceSensorSim

from gw_testing import built_gateway
from ros_helpers import wait_for

pytestmark = pytest.mark.ros
SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "teahouse-reception.yaml"


def ros_gateway(settings, mongo, folder, domain_id):
    settings.ros.domain_id = domain_id
    return built_gateway(settings, mongo, folder, ros=True)


def entrance_message(reading: dict) -> dict:
    """A scenario reading as the dict the node makes of a real Entrance message."""
    return to_dict(dict_to_entrance(reading))


def handle(gateway, reading: dict):
    """Feed one reading through the ingress of the ``entrance`` subscription (as the node does)."""
    sub = gateway.settings.ros.subscriptions[0]
    assert sub.topic == "entrance"
    return gateway.ros.ingress.handle(sub, entrance_message(reading))


def _one_group(customers=("a", "b")):
    """Readings that complete a detection of a pair walking up (1 Hz, like the papers)."""
    return [{"id": f"e{i}", "stamp": 1000.0 + i,
             "customers": [{"id": c, "distance": d, "age": 30, "gender": "female"} for c in customers]}
            for i, d in enumerate([5.0, 4.0, 3.0, 2.0, 1.8, 1.8])]


def test_scenario_reaches_the_robot_in_order_and_everything_is_recorded(domain_id, settings, mongo, tmp_path) -> None:
    with ros_gateway(settings, mongo, tmp_path, domain_id) as gateway, RosRuntime(domain_id=domain_id) as rt:
        robot = rt.make(RobotSim, "pepper")
        sensor = rt.make(EntranceSensorSim, load_scenario(SCENARIO), speed=4.0)
        assert wait_for(sensor.subscribed, 60)  # the gateway listens before the first reading goes out
        sensor.start()
        assert sensor.done.wait(30)
        # the scenario's last call (the party of four taken to its table); 60 s is a safety limit
        last = ("move_to", "table for four")
        assert wait_for(lambda: gateway.idle() and robot.calls and (
            robot.calls[-1]["service"], robot.calls[-1].get("location")) == last, 60), robot.calls
        store = gateway.store
        assert store.flush()
        said = [c["text"] for c in robot.calls if c["service"] == "speak"]
        assert said == ["Welcome. Two seats?", "Welcome. Three seats?"]
        seq = [(c["service"], c.get("location") or c.get("text") or c.get("name")) for c in robot.calls]
        first = seq[: seq.index(("speak", "Welcome. Three seats?"))]
        assert first[0] == ("move_to", "entrance") and ("speak", "Welcome. Two seats?") in first
        assert first.index(("speak", "Welcome. Two seats?")) < first.index(("move_to", "table for two"))
        rest = seq[len(first) - 1:]
        assert rest[0] == ("move_to", "entrance") and rest[-1] == ("move_to", "table for four")
        # the Information State holds every step, and every robot action is linked to its decision
        # the last readings may still be on their way in after the last call: wait for all of them
        assert wait_for(lambda: store.flush() and store.count("sensor_messages") == sensor.published, 30), (
            store.count("sensor_messages"), sensor.published)
        assert store.count("rdf_events") == sensor.published
        assert store.count("query_results") >= 2
        decisions, _ = gateway.decisions.find(origin="stream")
        assert len(decisions) == 2 and all(d["ruleset"] == "reception" for d in decisions)
        entrance = [f for f in decisions[-1]["facts"] if f["type"] == "Entrance"]
        assert entrance == [{"type": "Entrance", "id": "entrance", "number_of_customers": 2}]
        assert store.count("actions") == len(robot.calls)
        first_decision = gateway.decisions.get(decisions[-1]["decision_id"])
        assert [o["status"] for o in first_decision["outcomes"]] == ["ok"] * len(first_decision["actions"])
        # the same windows are the REST API's: the ROS-fed query shows them
        info = gateway.streams.query_info("CustomerDetectionQuery")
        assert info["stats"]["windows"] > 0 and info["stats"]["rule_fires"] == 2


def test_bad_sensor_values_are_rejected_recorded_and_do_not_stop_the_node(domain_id, settings, mongo,
                                                                          tmp_path) -> None:
    with ros_gateway(settings, mongo, tmp_path, domain_id) as gateway, RosRuntime(domain_id=domain_id) as rt:
        from rclpy.node import Node
        from printeps_interfaces.msg import Entrance

        pub_node = rt.make(Node, "bad_sensor")
        pub = pub_node.create_publisher(Entrance, "entrance", 100)
        assert wait_for(lambda: pub.get_subscription_count() > 0, 15)
        # the path is open both ways once a probe reading gets through (not after a guessed pause)
        probe = dict_to_entrance({"id": "probe", "customers": [{"id": "a", "distance": 2.0}], "stamp": 0.5})
        assert wait_for(lambda: pub.publish(probe) or gateway.ros.stats["readings"] > 0, 15, step=0.2)
        bad = [
            {"id": "neg", "customers": [{"id": "a", "distance": -1.0}], "stamp": 1.0},
            {"id": "nan", "customers": [{"id": "a", "distance": math.nan}], "stamp": 2.0},
            {"id": "many", "customers": [{"id": f"c{i}", "distance": 2.0} for i in range(1000)], "stamp": 3.0},
            {"id": "ok", "customers": [{"id": "a", "distance": 2.0}], "stamp": 4.0},
        ]
        for b in bad:
            pub.publish(dict_to_entrance(b))
        def accepted() -> set[str]:
            assert gateway.store.flush()
            return {d["message"]["id"]
                    for d in gateway.store.query("sensor_messages", type="printeps_interfaces/msg/Entrance")}

        assert wait_for(lambda: gateway.ros.stats["rejected"] == 3 and "ok" in accepted(), 15), gateway.ros.stats
        assert gateway.ros.stats["rejected"] == 3 and accepted() == {"probe", "ok"}
        rejected = {d["message"]["id"]: d["error"]["field"]
                    for d in gateway.store.query("sensor_messages", type="printeps/RejectedMessage")}
    assert rejected == {"neg": "customers[0].distance", "nan": "customers[0].distance",
                        "many": "number_of_customers"}


def test_missing_robot_service_is_retried_then_recorded(domain_id, settings, mongo, tmp_path) -> None:
    settings.ros.robots = {"pepper": "/nobody_here"}
    settings.ros.call_timeout_s = 0.3
    settings.ros.call_retries = 1
    with ros_gateway(settings, mongo, tmp_path, domain_id) as gateway:
        for reading in _one_group():
            handle(gateway, reading)
        assert wait_for(gateway.idle, 30)
        assert gateway.store.flush()
        outcomes = gateway.store.query("actions")
        assert outcomes and {o["status"] for o in outcomes} == {"no_service"}
        assert all(o["attempts"] == 2 and o["decision_id"] for o in outcomes)


def test_hanging_robot_times_out_then_recorded(domain_id, settings, mongo, tmp_path) -> None:
    settings.ros.call_timeout_s = 0.4
    settings.ros.call_retries = 1
    with RosRuntime(domain_id=domain_id) as robot_rt, ros_gateway(settings, mongo, tmp_path, domain_id) as gateway:
        robot_rt.make(RobotSim, "pepper", hang_s=1.5)
        client = gateway.ros.caller.client("/pepper/speak", "printeps_interfaces/srv/Speak")
        assert wait_for(client.service_is_ready, 15)
        for reading in _one_group():
            handle(gateway, reading)
        assert wait_for(gateway.idle, 60)
        assert gateway.store.flush()
        outcomes = gateway.store.query("actions", newest_first=False)
    assert outcomes and outcomes[0]["status"] == "timeout" and outcomes[0]["attempts"] == 2
    assert "did not answer within 0.4 s" in outcomes[0]["message"]


def test_fire_business_rules_service(domain_id, settings, mongo, tmp_path) -> None:
    from rclpy.node import Node
    from printeps_interfaces.srv import FireBusinessRules

    facts = [{"type": "Entrance", "id": "entrance", "number_of_customers": 1},
             {"type": "Customer", "id": "a", "entrance": "entrance", "age": 30, "gender": "male", "distance": 2.0},
             {"type": "Robot", "id": "pepper", "position": "entrance"}]
    with ros_gateway(settings, mongo, tmp_path, domain_id) as gateway, RosRuntime(domain_id=domain_id) as rt:
        client = rt.make(Node, "workflow").create_client(FireBusinessRules, "fire_business_rules")
        assert client.wait_for_service(timeout_sec=15)
        res = client.call(FireBusinessRules.Request(ruleset="reception", facts_json=json.dumps(facts),
                                                    request_id="greeting-run-7"), timeout_sec=10)
        assert res.success and res.version >= 1 and res.decision_id
        assert any(a["params"].get("text", "").startswith("Welcome.") for a in json.loads(res.actions_json))
        bad = client.call(FireBusinessRules.Request(ruleset="reception", facts_json='[{"type": '), timeout_sec=10)
        assert not bad.success and json.loads(bad.error)["column"] > 1
        missing = client.call(FireBusinessRules.Request(ruleset="nope", facts_json="[]"), timeout_sec=10)
        assert not missing.success and "nope" in missing.error
        assert gateway.store.flush()
        decision = gateway.decisions.get(res.decision_id)
        assert decision["origin"] == "ros" and decision["correlation_id"] == "greeting-run-7"


def test_gateway_restart_mid_scenario_loses_nothing(domain_id, settings, mongo, tmp_path) -> None:
    from gw_testing import open_test_store
    from gateway.app import build_gateway

    scenario = load_scenario(SCENARIO)
    readings = list(scenario.readings(start=5000.0))
    half = len(readings) // 2
    calls = []
    settings.ros.domain_id = domain_id
    store = open_test_store(mongo, tmp_path)
    try:
        with RosRuntime(domain_id=domain_id) as robot_rt:
            robot_rt.make(RobotSim, "pepper", on_call=calls.append)
            for part in (readings[:half], readings[half:]):  # the gateway is stopped and started in between
                gateway = build_gateway(settings, store=store, ros=True, warm_up=False)
                try:
                    client = gateway.ros.caller.client("/pepper/speak", "printeps_interfaces/srv/Speak")
                    assert wait_for(client.service_is_ready, 15)
                    for r in part:
                        handle(gateway, dict(r))
                    assert wait_for(gateway.idle, 30)
                finally:
                    gateway.close()
        assert store.flush()
        assert store.count("sensor_messages") == len(readings)
        assert [c["text"] for c in calls if c["service"] == "speak"] == ["Welcome. Two seats?", "Welcome. Three seats?"]
    finally:
        store.close()


def test_a_rest_deploy_changes_what_the_robot_says_next(domain_id, settings, mongo, tmp_path) -> None:
    """One gateway: a deploy through REST (the workbench's path) changes the text of the next Speak
    request the simulated robot receives after an entrance message."""
    from fastapi.testclient import TestClient

    with ros_gateway(settings, mongo, tmp_path, domain_id) as gateway, RosRuntime(domain_id=domain_id) as rt:
        robot = rt.make(RobotSim, "pepper")
        client = gateway.ros.caller.client("/pepper/speak", "printeps_interfaces/srv/Speak")
        assert wait_for(client.service_is_ready, 15)
        http = TestClient(gateway.app)
        current = http.get("/api/rulesets/reception").json()
        # the rules and their test scenarios (a red scenario would refuse the deploy)
        files = {name: text.replace("Welcome. Two seats?", "Hello, you two! A table?")
                 for name, text in current["files"].items()}
        assert files != current["files"]
        deployed = http.put("/api/rulesets/reception", json={"files": files, "comment": "friendlier",
                                                              "base_version": current["version"]})
        assert deployed.status_code == 201, deployed.text
        for reading in _one_group():
            handle(gateway, reading)
        assert wait_for(lambda: any(c["service"] == "speak" for c in robot.calls), 30), robot.calls
        said = [c["text"] for c in robot.calls if c["service"] == "speak"]
        assert said == ["Hello, you two! A table?"]


def test_leaving_seat_over_ros_clears_the_table(domain_id, settings, mongo, tmp_path) -> None:
    """Table sensors (TeahouseObject on ROS) → the tables RDF stream → LeavingSeatQuery (empty for
    the ontology's tableEmptyTime after a party sat there) → the table_service rules → the
    clear_table workflow → Pepper goes to the table, the staff clear it, Pepper returns."""
    from gateway.ros.scenario import TableScenario
    from gateway.ros.sim_tables import TableSensorSim

    plan = TableScenario.model_validate({
        "name": "one party leaves", "rate_hz": 2, "duration": 32, "tables": ["table1", "table2"],
        "parties": [{"table": "table2", "people": ["a", "b"], "from": 0, "to": 6}]})
    with ros_gateway(settings, mongo, tmp_path, domain_id) as gateway, RosRuntime(domain_id=domain_id) as rt:
        robot = rt.make(RobotSim, "pepper")
        assert wait_for(gateway.ros.caller.client("/pepper/move_to", "printeps_interfaces/srv/MoveTo").service_is_ready, 15)
        sensors = rt.make(TableSensorSim, plan, speed=4.0)
        sensors.start()
        assert sensors.done.wait(30)
        assert wait_for(lambda: gateway.idle() and len(robot.calls) >= 2, 30), robot.calls
        moves = [c["location"] for c in robot.calls if c["service"] == "move_to"]
        assert moves == ["table2", "counter"], robot.calls
        assert gateway.store.flush()
        decisions, _ = gateway.decisions.find(ruleset="table_service")
        assert len(decisions) == 1 and decisions[0]["origin"] == "stream"
        assert decisions[0]["facts"][0]["type"] == "TableLeft" and decisions[0]["facts"][0]["table"] == "table2"
        outcome = gateway.decisions.get(decisions[0]["decision_id"])["outcomes"][0]
        assert outcome["status"] == "ok" and outcome["run_id"]
        assert gateway.robots.position("pepper") == "counter"


def test_start_up_parameter_overrides_reach_the_dispatcher(domain_id, settings, mongo, tmp_path) -> None:
    """``--ros-args -p`` values given at start-up are applied once the dispatcher exists (they were
    read while it did not, and only ``ruleset`` took effect)."""
    settings.ros.args = ["--ros-args", "-p", "call_timeout_s:=0.7", "-p", "call_retries:=0",
                         "-p", "robots:=[pepper=/elsewhere]", "-p", "ruleset:=reception_greetings"]
    with ros_gateway(settings, mongo, tmp_path, domain_id) as gateway:
        dispatcher = gateway.ros.dispatcher
        assert dispatcher.timeout_s == 0.7
        assert dispatcher.retries == 0
        assert dispatcher.robots == {"pepper": "/elsewhere"}
        assert gateway.ros.node.ruleset == "reception_greetings"


def test_a_start_up_parameter_out_of_range_is_refused_by_name(domain_id, settings, mongo, tmp_path) -> None:
    settings.ros.args = ["--ros-args", "-p", "call_retries:=99"]
    with pytest.raises(ValueError, match="call_retries: must be in"):
        with ros_gateway(settings, mongo, tmp_path, domain_id):
            pass


def test_a_message_the_stream_refuses_is_still_recorded_with_why(domain_id, settings, mongo, tmp_path) -> None:
    """A reading that maps but is refused by the stream engine (here: more triples than a message may
    hold) is recorded as rejected with the stream's reason, never lost silently."""
    settings.streams.max_message_triples = 3
    with ros_gateway(settings, mongo, tmp_path, domain_id) as gateway:
        reading = {"id": "big", "stamp": 5.0,
                   "customers": [{"id": c, "distance": 2.0, "age": 30, "gender": "female"} for c in "abc"]}
        assert handle(gateway, reading) is None
        assert gateway.ros.stats["rejected"] == 1 and gateway.ros.stats["readings"] == 0
        assert gateway.store.flush()
        rejected = gateway.store.query("sensor_messages", type="printeps/RejectedMessage")
    assert [d["message"]["id"] for d in rejected] == ["big"]
    assert "at most 3 triples" in rejected[0]["error"]["message"]
