"""The gateway ROS node: configured topics in, robot service calls out, ``fire_business_rules`` served.

Thin adapter: subscription callbacks turn a message into a dict and queue it for the ingress
(:mod:`gateway.ros.ingress`); the rule firing behind ``fire_business_rules`` is the gateway's one
engine; robot services are called through :class:`RosServiceCaller`, which the action dispatcher
and the workflows' ROS modules share. Message and service types are imported by name from the
configuration, so no code is written per type. Parameters come from the config file
(settings.ros) and can be overridden as ROS parameters: ruleset, call_timeout_s, call_retries,
robots (["pepper=/pepper", ...]).
"""

from __future__ import annotations

import json
import logging
import threading
import time
from typing import Any, Callable

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rcl_interfaces.msg import SetParametersResult

from gateway.ros.convert import ConversionError, fill, import_type, to_dict

log = logging.getLogger(__name__)

Fire = Callable[[str, list[dict[str, Any]], str | None], Any]


class RosServiceCaller:
    """Calls any ROS service by name and type (clients created once per service, then reused)."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self._clients: dict[tuple[str, str], Any] = {}
        self._lock = threading.Lock()
        self._group = ReentrantCallbackGroup()

    def client(self, service: str, type_name: str) -> Any:
        with self._lock:
            key = (service, type_name)
            if key not in self._clients:
                self._clients[key] = self.node.create_client(import_type(type_name), service, callback_group=self._group)
            return self._clients[key]

    def call(self, service: str, type_name: str, params: dict[str, Any], timeout_s: float, *,
             strict: bool = True) -> tuple[str, str, dict[str, Any]]:
        """(status, message, response) with status ok / failed / timeout / no_service."""
        client = self.client(service, type_name)
        deadline = time.monotonic() + timeout_s
        if not client.service_is_ready() and not client.wait_for_service(timeout_sec=timeout_s):
            return "no_service", f"{service} is not available (waited {timeout_s:g} s)", {}
        try:
            request = fill(import_type(type_name).Request(), params, f"{service} request", strict=strict)
        except ConversionError as exc:
            return "failed", str(exc), {}
        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(max(0.0, deadline - time.monotonic())):
            client.remove_pending_request(future)
            future.cancel()
            return "timeout", f"{service} did not answer within {timeout_s:g} s", {}
        if future.exception() is not None:
            return "failed", f"{service}: {future.exception()}", {}
        response = to_dict(future.result())
        ok = response.get("success", True) is not False
        return ("ok" if ok else "failed"), str(response.get("message", "")), response

    def __call__(self, service: str, type_name: str, params: dict[str, Any], timeout_s: float) -> tuple[str, str]:
        """The dispatcher's ServiceCaller: rule actions may carry parameters the request lacks."""
        status, message, _ = self.call(service, type_name, params, timeout_s, strict=False)
        return status, message


def parameter_problem(params: list[Parameter]) -> str | None:
    """What is wrong with the first bad value among ``params`` (None when all are acceptable)."""
    for p in params:
        if p.name == "robots" and any("=" not in item for item in p.value if item):
            return "robots: each item must be name=/namespace"
        if p.name == "call_timeout_s" and not 0 < float(p.value) <= 60:
            return "call_timeout_s: must be in (0, 60]"
        if p.name == "call_retries" and not 0 <= int(p.value) <= 10:
            return "call_retries: must be in [0, 10]"
    return None


class GatewayNode(Node):
    """Subscribes the configured topics, serves fire_business_rules, calls robot services."""

    def __init__(self, ros_settings: Any, *, enqueue: Callable[[int, dict[str, Any]], None], fire: Fire,
                 dispatcher: Any = None, context: Any = None) -> None:
        super().__init__(ros_settings.node_name, context=context)
        self.cfg = ros_settings
        self.fire = fire
        self.dispatcher = dispatcher
        self.caller = RosServiceCaller(self)
        self.declare_parameter("ruleset", ros_settings.ruleset)
        self.declare_parameter("call_timeout_s", float(ros_settings.call_timeout_s))
        self.declare_parameter("call_retries", int(ros_settings.call_retries))
        self.declare_parameter("robots", [f"{k}={v}" for k, v in ros_settings.robots.items()] or [""])
        self.ruleset = ros_settings.ruleset
        self._apply(self.get_parameters(["ruleset", "call_timeout_s", "call_retries", "robots"]))
        self.add_on_set_parameters_callback(self._on_params)
        group = ReentrantCallbackGroup()
        for index, sub in enumerate(ros_settings.subscriptions):
            self.create_subscription(import_type(sub.type), sub.topic,
                                     lambda m, i=index: enqueue(i, to_dict(m)), 100, callback_group=group)
        from printeps_interfaces.srv import FireBusinessRules

        self.create_service(FireBusinessRules, "fire_business_rules", self._on_fire, callback_group=group)

    # ---- parameters --------------------------------------------------------------------------
    def attach_dispatcher(self, dispatcher: Any) -> None:
        """Hand the robot calls to ``dispatcher`` and apply the node's parameters to it.

        Why now: the parameters are declared (and start-up overrides such as ``--ros-args -p
        call_timeout_s:=3.0`` read) before the dispatcher exists, so until it is attached only
        ``ruleset`` can take effect. A start-up value the live setter would refuse is refused here too."""
        params = self.get_parameters(["ruleset", "call_timeout_s", "call_retries", "robots"])
        problem = parameter_problem(params)
        if problem is not None:
            raise ValueError(f"ROS parameter {problem}")
        self.dispatcher = dispatcher
        self._apply(params)

    def _apply(self, params: list[Parameter]) -> None:
        for p in params:
            if p.name == "ruleset":
                self.ruleset = str(p.value)
            elif self.dispatcher is None:
                continue
            elif p.name == "call_timeout_s":
                self.dispatcher.timeout_s = float(p.value)
            elif p.name == "call_retries":
                self.dispatcher.retries = int(p.value)
            elif p.name == "robots":
                self.dispatcher.robots = dict(item.split("=", 1) for item in p.value if "=" in item)

    def _on_params(self, params: list[Parameter]) -> SetParametersResult:
        problem = parameter_problem(params)
        if problem is not None:
            return SetParametersResult(successful=False, reason=problem)
        self._apply(params)
        return SetParametersResult(successful=True)

    # ---- fire_business_rules ------------------------------------------------------------------
    def _on_fire(self, req: Any, res: Any) -> Any:
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
        try:
            result = self.fire(req.ruleset or self.ruleset, facts, req.request_id or None)
        except Exception as exc:
            body = exc.to_dict() if hasattr(exc, "to_dict") else {}
            res.error = json.dumps({**body, "error": str(exc) or type(exc).__name__}, default=str)
            return res
        res.success = True
        res.actions_json = json.dumps(result.actions, default=str)
        res.version = int(result.version or 0)
        res.decision_id = result.decision_id or ""
        return res
