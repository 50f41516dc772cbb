"""The gateway ROS node: entrance topics in, robot service calls out, ``fire_business_rules`` served.

Thin adapter around gateway.ros.pipeline.Pipeline: subscription callbacks only convert a message to
a dict and queue it (bounded); one worker thread runs the pipeline in order, so rule firing and
robot calls never block the executor, and service responses keep arriving while it waits.
Parameters come from the config file (settings.ros) and can be overridden as ROS parameters:
ruleset, call_timeout_s, call_retries, robots (["pepper=/pepper", ...]).
"""

from __future__ import annotations

import json
import logging
import queue
import threading
import time
from typing import Any, Callable

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rcl_interfaces.msg import SetParametersResult

from gateway.ros.convert import entrance_sensor_to_dict, entrance_to_dict
from gateway.store.store import SENSOR_MESSAGES

from printeps_interfaces.msg import Entrance, EntranceSensor
from printeps_interfaces.srv import FireBusinessRules, Gesture, MoveTo, Speak

log = logging.getLogger(__name__)

SRV_TYPES = {"Speak": Speak, "MoveTo": MoveTo, "Gesture": Gesture}


def _request(kind: str, params: dict[str, Any]) -> Any:
    robot = str(params.get("robot", ""))
    if kind == "Speak":
        return Speak.Request(robot=robot, text=str(params.get("text", "")))
    if kind == "MoveTo":
        return MoveTo.Request(robot=robot, location=str(params.get("location", "")),
                              x=float(params.get("x", 0.0)), y=float(params.get("y", 0.0)))
    return Gesture.Request(robot=robot, name=str(params.get("name", "")))


class RosServiceCaller:
    """The dispatcher's ServiceCaller over rclpy clients (created once per service, then reused)."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self._clients: dict[str, Any] = {}
        self._lock = threading.Lock()
        self._group = ReentrantCallbackGroup()

    def client(self, service: str, kind: str) -> Any:
        with self._lock:
            if service not in self._clients:
                self._clients[service] = self.node.create_client(SRV_TYPES[kind], service,
                                                                 callback_group=self._group)
            return self._clients[service]

    def __call__(self, service: str, kind: str, params: dict[str, Any], timeout_s: float) -> tuple[str, str]:
        client = self.client(service, kind)
        deadline = time.monotonic() + timeout_s
        if not client.service_is_ready() and not client.wait_for_service(timeout_sec=timeout_s):
            return "no_service", f"{service} is not available (waited {timeout_s:g} s)"
        done = threading.Event()
        future = client.call_async(_request(kind, params))
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(max(0.0, deadline - time.monotonic())):
            client.remove_pending_request(future)
            future.cancel()
            return "timeout", f"{service} did not answer within {timeout_s:g} s"
        if future.exception() is not None:
            return "failed", f"{service}: {future.exception()}"
        res = future.result()
        return ("ok" if res.success else "failed"), res.message


class GatewayNode(Node):
    """Subscribes the entrance topics, feeds the pipeline from one worker, serves fire_business_rules."""

    def __init__(self, ros_settings: Any, pipeline_factory: Callable[["GatewayNode"], Any],
                 rules: Callable[[str, list[dict[str, Any]]], dict[str, Any]] | None = None,
                 store: Any = None, context: Any = None) -> None:
        super().__init__(ros_settings.node_name, context=context)
        self.cfg = ros_settings
        self.store = store
        self.rules = rules
        self.declare_parameter("ruleset", ros_settings.ruleset)
        self.declare_parameter("call_timeout_s", float(ros_settings.call_timeout_s))
        self.declare_parameter("call_retries", int(ros_settings.call_retries))
        self.declare_parameter("robots", [f"{k}={v}" for k, v in ros_settings.robots.items()] or [""])
        self.caller = RosServiceCaller(self)
        self.pipeline = pipeline_factory(self)
        self._apply(self.get_parameters(["ruleset", "call_timeout_s", "call_retries", "robots"]))
        self.add_on_set_parameters_callback(self._on_params)
        self.queue: queue.Queue[tuple[dict[str, Any], str]] = queue.Queue(maxsize=ros_settings.queue_size)
        self._stop = threading.Event()
        group = ReentrantCallbackGroup()
        for topic in ros_settings.entrance_topics:
            self.create_subscription(Entrance, topic, lambda m, t=topic: self._enqueue(entrance_to_dict(m), t),
                                     100, callback_group=group)
        for topic in ros_settings.entrance_sensor_topics:
            self.create_subscription(EntranceSensor, topic,
                                     lambda m, t=topic: self._enqueue(entrance_sensor_to_dict(m), t), 100,
                                     callback_group=group)
        self.create_service(FireBusinessRules, "fire_business_rules", self._on_fire, callback_group=group)
        self._worker = threading.Thread(target=self._work, name="gateway-pipeline", daemon=True)
        self._worker.start()
        self.get_logger().info(f"gateway node up: topics {ros_settings.entrance_topics} + "
                               f"{ros_settings.entrance_sensor_topics}, robots {self.pipeline.dispatcher.robots}")

    # ---- parameters ---------------------------------------------------------------------------
    def _apply(self, params: list[Parameter]) -> None:
        disp = self.pipeline.dispatcher
        for p in params:
            if p.name == "ruleset":
                self.pipeline.ruleset = p.value
            elif p.name == "call_timeout_s":
                disp.timeout_s = float(p.value)
            elif p.name == "call_retries":
                disp.retries = int(p.value)
            elif p.name == "robots":
                disp.robots = dict(item.split("=", 1) for item in p.value if "=" in item)

    def _on_params(self, params: list[Parameter]) -> SetParametersResult:
        for p in params:
            if p.name == "robots" and any("=" not in item for item in p.value):
                return SetParametersResult(successful=False, reason="robots: each item must be name=/namespace")
            if p.name == "call_timeout_s" and not 0 < float(p.value) <= 60:
                return SetParametersResult(successful=False, reason="call_timeout_s: must be in (0, 60]")
            if p.name == "call_retries" and not 0 <= int(p.value) <= 10:
                return SetParametersResult(successful=False, reason="call_retries: must be in [0, 10]")
        self._apply(params)
        return SetParametersResult(successful=True)

    # ---- topics → worker ----------------------------------------------------------------------
    def _enqueue(self, reading: dict[str, Any], topic: str) -> None:
        try:
            self.queue.put_nowait((reading, topic))
        except queue.Full:
            log.error("gateway queue full (%d): reading %s from %s recorded, not processed",
                      self.queue.maxsize, reading.get("id"), topic)
            if self.store is not None:
                self.store.record(SENSOR_MESSAGES, {"source": topic, "reading": reading,
                                                    "error": {"field": "", "message": "gateway queue full"}},
                                  stored_type="printeps/RejectedEntrance", inserted_by="gateway_node")

    def _work(self) -> None:
        while not self._stop.is_set():
            try:
                reading, topic = self.queue.get(timeout=0.2)
            except queue.Empty:
                continue
            try:
                self.pipeline.on_reading(reading, topic)
            except Exception:
                log.exception("pipeline failed on reading %s", reading.get("id"))

    def stop(self) -> None:
        """Let the worker finish the reading in hand, then stop (called by RosRuntime.shutdown)."""
        self._stop.set()
        if self._worker.is_alive() and threading.current_thread() is not self._worker:
            self._worker.join(timeout=5.0)

    # ---- fire_business_rules ------------------------------------------------------------------
    def _on_fire(self, req: FireBusinessRules.Request, res: FireBusinessRules.Response) -> Any:
        res.success = False
        try:
            facts = json.loads(req.facts_json or "[]")
        except json.JSONDecodeError as exc:
            res.error = json.dumps({"error": "facts_json is not JSON", "line": exc.lineno, "column": exc.colno,
                                    "message": exc.msg})
            return res
        if not isinstance(facts, list) or not all(isinstance(f, dict) for f in facts):
            res.error = json.dumps({"error": "facts_json must be a JSON list of objects"})
            return res
        if self.rules is None:
            res.error = json.dumps({"error": "no rules engine on this gateway"})
            return res
        try:
            result = self.rules(req.ruleset or self.pipeline.ruleset, facts)
        except Exception as exc:
            body = exc.to_dict() if hasattr(exc, "to_dict") else {}
            res.error = json.dumps({**body, "error": str(exc) or type(exc).__name__}, default=str)
            return res
        res.success = True
        res.actions_json = json.dumps(result.get("actions", []), default=str)
        res.version = int(result.get("version") or 0)
        return res
