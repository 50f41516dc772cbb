"""``ros_service``/``ros_topic`` modules over the gateway's ROS node: the edge between workflows and robots.

Why through the gateway node: one process, one ROS context, one executor (see
:mod:`gateway.ros.bridge`). The executor calls modules from worker threads; service calls go
through the node's :class:`~gateway.ros.node.RosServiceCaller` (``call_async`` + a bounded wait,
never ``spin_until_future_complete`` from a worker). Publishers are created on first use per
(topic, type). Types are named like ``printeps_interfaces/srv/Speak``.
"""

from __future__ import annotations

import threading
from typing import Any

from gateway.ros.convert import ConversionError, fill, import_type
from gateway.workflow.adapters import Call, ModuleFailed


class RosModules:
    """Calls ROS 2 services and publishes to topics for workflow modules, on a given node."""

    def __init__(self, node: Any, caller: Any, on_move: Any = None) -> None:
        self.node = node
        self.caller = caller
        self.on_move = on_move  # robot positions follow a workflow's moves too
        self._publishers: dict[tuple[str, str], Any] = {}
        self._lock = threading.Lock()

    def call(self, call: Call) -> dict[str, Any]:
        if call.module.kind == "ros_topic":
            return self._publish(call)
        return self._call_service(call)

    def _call_service(self, call: Call) -> dict[str, Any]:
        name, type_name = call.module.options["service"], call.module.options["type"]
        status, message, response = self.caller.call(name, type_name, call.params, call.timeout)
        if status == "no_service":
            raise TimeoutError(f"service {name} ({type_name}) is not available")
        if status == "timeout":
            raise TimeoutError(f"service {name} did not answer within {call.timeout}s")
        if status != "ok":
            if response.get("success") is False:
                raise ModuleFailed(f"service {name} answered success=false: {message}")
            raise ModuleFailed(message)
        if self.on_move is not None and type_name.endswith("/MoveTo"):
            self.on_move({"status": "ok", "action": {"module": "move", "params": dict(call.params)}})
        return response

    def _publish(self, call: Call) -> dict[str, Any]:
        name, type_name = call.module.options["topic"], call.module.options["type"]
        msg_type = import_type(type_name)
        with self._lock:
            publisher = self._publishers.get((name, type_name))
            if publisher is None:
                publisher = self._publishers[(name, type_name)] = self.node.create_publisher(msg_type, name, 10)
        try:
            message = fill(msg_type(), call.params, f"{call.module.name} message")
        except ConversionError as exc:
            raise ModuleFailed(str(exc)) from None
        publisher.publish(message)
        return {"published": name}

    def close(self) -> None:
        """The node belongs to the gateway: nothing to stop here."""
