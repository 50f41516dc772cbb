"""The dialogue over ROS with real rclpy nodes: customers' Utterance messages in, Pepper's answers
through her Speak service, the completed order published on /teahouse/orders (JSON) and kept in
the Information State."""

from __future__ import annotations

import json
import wave

import pytest
from rclpy.node import Node
from std_msgs.msg import String

from gateway.ros.runtime import RosRuntime
from gateway.ros.sim_robot import RobotSim

from gw_testing import built_gateway
from ros_helpers import wait_for

pytestmark = pytest.mark.ros


class Customer(Node):
    """A table's tablet/recogniser: publishes utterances, hears the orders."""

    def __init__(self, context=None) -> None:
        super().__init__("customer_table1", context=context)
        from printeps_interfaces.msg import Utterance

        self.Utterance = Utterance
        self.publisher = self.create_publisher(Utterance, "/teahouse/utterances", 10)
        self.orders: list[dict] = []
        self.create_subscription(String, "/teahouse/orders", lambda m: self.orders.append(json.loads(m.data)), 10)

    def say(self, conversation: str, text: str, confidence: float = 1.0) -> None:
        self.publisher.publish(self.Utterance(conversation=conversation, text=text, confidence=confidence))


def test_an_order_taken_over_ros_reaches_pepper_the_topic_and_the_information_state(domain_id, settings, mongo,
                                                                                     tmp_path) -> None:
    settings.ros.domain_id = domain_id
    with built_gateway(settings, mongo, tmp_path, ros=True) as gateway, RosRuntime(domain_id=domain_id) as rt:
        pepper = rt.make(RobotSim, "pepper", speech_dir=tmp_path / "speech")
        customer = rt.make(Customer)
        assert wait_for(lambda: customer.publisher.get_subscription_count() >= 1, 20)  # the gateway listens

        def said() -> list[str]:
            return [c["text"] for c in pepper.calls if c["service"] == "speak"]

        customer.say("table1", "coffee please")
        assert wait_for(lambda: "How many cups of coffee?" in said(), 30), said()
        customer.say("table1", "two")
        assert wait_for(lambda: "2 coffees, certainly. Is that right?" in said(), 30), said()
        customer.say("table1", "yes")
        assert wait_for(lambda: customer.orders, 30)
        order = customer.orders[-1]
        assert (order["conversation"], order["table"], order["drink"], order["cups"]) == ("table1", "table1", "coffee", 2)
        assert len(order["decision_ids"]) == 3 and order["at"]
        assert wait_for(lambda: "Thank you. Your coffees will be ready soon." in said(), 30), said()
        spoken = next(c for c in pepper.calls if c.get("text") == "2 coffees, certainly. Is that right?")
        with wave.open(spoken["audio"]) as w:  # the simulated Pepper really spoke it
            assert w.getnframes() > w.getframerate()
        assert gateway.store.flush()
        stored = gateway.store.query("orders", filters={"conversation": "table1"})
        assert stored and stored[0]["decision_ids"] == order["decision_ids"]


def test_an_utterance_continues_a_conversation_another_process_began(domain_id, settings, mongo, tmp_path) -> None:
    """The conversation is in the Information State: a gateway that never saw its first turn
    (another worker, another host, or this one restarted) continues it from the ROS topic."""
    from fastapi.testclient import TestClient

    from gateway.app import build_gateway
    from gw_testing import open_test_store

    settings.ros.domain_id = domain_id
    store = open_test_store(mongo, tmp_path)
    try:
        first = build_gateway(settings, store=store, ros=False, warm_up=False)
        try:
            asked = TestClient(first.app).post("/api/dialogue/turns", json={"conversation": "table4", "text": "coffee please"})
            assert asked.status_code == 200 and asked.json()["says"] == ["How many cups of coffee?"], asked.text
        finally:
            first.close()
        with RosRuntime(domain_id=domain_id) as rt:
            second = build_gateway(settings, store=store, ros=True, warm_up=False)
            try:
                pepper = rt.make(RobotSim, "pepper", speech_dir=tmp_path / "speech")
                customer = rt.make(Customer)
                assert wait_for(lambda: customer.publisher.get_subscription_count() >= 1, 20)
                customer.say("table4", "two")

                def said() -> list[str]:
                    return [c["text"] for c in pepper.calls if c["service"] == "speak"]

                assert wait_for(lambda: "2 coffees, certainly. Is that right?" in said(), 30), said()
                going = TestClient(second.app).get("/api/dialogue/conversations").json()["going_on"]
                assert [(c["turns"], c["state"]) for c in going if c["conversation"] == "table4"] == [(2, "confirming")]
            finally:
                second.close()
    finally:
        store.close()
