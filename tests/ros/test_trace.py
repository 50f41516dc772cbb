"""A trace over the ROS path (real rclpy nodes, real engine, real Information State): one
correlation id leads from the sensor messages through the RDF items, the query result and the
decision to the robot's actions and their outcomes, in time order."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from gateway.ros.runtime import RosRuntime
from gateway.ros.sim_robot import RobotSim

from ros_helpers import wait_for
from test_node import _one_group, handle, ros_gateway

pytestmark = pytest.mark.ros


def test_a_sensor_to_robot_chain_is_traced_in_order(domain_id, settings, mongo, tmp_path) -> None:
    with ros_gateway(settings, mongo, tmp_path, domain_id) as gateway, RosRuntime(domain_id=domain_id) as rt:
        robot = rt.make(RobotSim, "pepper")
        client = gateway.ros.caller.client("/pepper/speak", "printeps_interfaces/srv/Speak")
        assert wait_for(client.service_is_ready, 15)
        for reading in _one_group():
            handle(gateway, reading)
        assert wait_for(lambda: gateway.idle() and any(c["service"] == "speak" for c in robot.calls), 30), robot.calls
        assert gateway.store.flush()
        decisions, _ = gateway.decisions.find(origin="stream")
        assert len(decisions) == 1
        decision = decisions[0]
        assert wait_for(lambda: gateway.store.flush() and len(gateway.decisions.get(decision["decision_id"])
                                                             ["outcomes"]) == len(decision["actions"]), 20)
        http = TestClient(gateway.app)
        answer = http.get(f"/api/traces/{decision['correlation_id']}")
        assert answer.status_code == 200, answer.text
        items = answer.json()["items"]
        kinds = [i["kind"] for i in items]
        firsts = [kinds.index(k) for k in ("sensor_message", "rdf_item", "query_result", "decision", "action")]
        assert firsts == sorted(firsts), kinds
        assert kinds.count("action") == len(decision["actions"]) == len(robot.calls)
        assert kinds.count("decision") == 1 and kinds.count("query_result") == 1
        window = decision["context"]["window"]
        stamps = [i["record"]["stamp_ms"] for i in items if i["kind"] in ("sensor_message", "rdf_item")]
        assert stamps and all(window["start"] <= s <= window["end"] for s in stamps)
        assert [i["t"] for i in items] == sorted(i["t"] for i in items) and items[0]["t"] > 1.7e9  # written now
        assert items[-1]["at"][:4] == items[0]["at"][:4] >= "2025"
        assert all(i["since_previous_ms"] >= 0 for i in items[1:])
        assert {h["to"] for h in answer.json()["hops"]} >= {"rdf_item", "query_result", "decision", "action"}
        said = [i["record"]["action"]["params"].get("text") for i in items if i["kind"] == "action"
                and i["record"]["action"]["module"] == "say"]
        assert said == [c["text"] for c in robot.calls if c["service"] == "speak"]
