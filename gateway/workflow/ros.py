"""``ros_service``/``ros_topic`` modules over real ROS 2 (rclpy): the edge between workflows and robots.

Why its own node: the executor calls modules from worker threads, so this adapter owns one rclpy node
spun by a background ``SingleThreadedExecutor`` thread and uses ``client.call_async`` + a bounded
wait (never ``spin_until_future_complete`` from a worker). Clients and publishers are created on
first use per (name, type). Types are named like ``printeps_interfaces/srv/Speak``.
"""

from __future__ import annotations

import importlib
import threading
from typing import Any

from gateway.workflow.adapters import Call, ModuleFailed


def import_type(name: str) -> Any:
    """``pkg/srv/Name`` or ``pkg/msg/Name`` -> the generated Python class."""
    package, kind, cls = name.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), cls)


def fill(message: Any, values: dict[str, Any], where: str) -> Any:
    """Set fields of a ROS message from a dict; unknown fields are an error naming the field."""
    fields = message.get_fields_and_field_types()
    for key, value in values.items():
        if key not in fields:
            raise ModuleFailed(f"{where}: {type(message).__name__} has no field {key!r} "
                               f"(fields: {', '.join(fields)})")
        kind = fields[key]
        try:
            if kind in ("float", "double"):
                value = float(value)
            elif kind.startswith(("int", "uint")) or kind in ("byte", "octet"):
                value = int(value)
            elif kind == "string":
                value = str(value)
            elif kind == "boolean":
                value = bool(value)
            elif isinstance(value, dict):
                value = fill(getattr(message, key), value, f"{where}.{key}")
            setattr(message, key, value)
        except (TypeError, ValueError, AssertionError) as exc:
            raise ModuleFailed(f"{where}.{key}: cannot set {value!r} as {kind}: {exc}") from None
    return message


def to_dict(message: Any) -> Any:
    """A ROS message as plain JSON-like data."""
    if hasattr(message, "get_fields_and_field_types"):
        return {k: to_dict(getattr(message, k)) for k in message.get_fields_and_field_types()}
    if isinstance(message, (list, tuple)):
        return [to_dict(v) for v in message]
    if hasattr(message, "tolist"):
        return message.tolist()
    return message


class RclpyAdapter:
    """Calls ROS 2 services and publishes to topics for workflow modules."""

    def __init__(self, node_name: str = "printeps_workflows") -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self._rclpy = rclpy
        self._owns_context = not rclpy.ok()
        if self._owns_context:
            rclpy.init()
        self.node = rclpy.create_node(node_name)
        self._executor = SingleThreadedExecutor()
        self._executor.add_node(self.node)
        self._thread = threading.Thread(target=self._executor.spin, daemon=True, name="workflow-rclpy")
        self._thread.start()
        self._clients: dict[tuple[str, str], Any] = {}
        self._publishers: dict[tuple[str, str], Any] = {}
        self._lock = threading.Lock()

    def call(self, call: Call) -> dict[str, Any]:
        if call.module.kind == "ros_topic":
            return self._publish(call)
        return self._call_service(call)

    def _call_service(self, call: Call) -> dict[str, Any]:
        name, type_name = call.module.options["service"], call.module.options["type"]
        srv = import_type(type_name)
        with self._lock:
            client = self._clients.get((name, type_name))
            if client is None:
                client = self._clients[(name, type_name)] = self.node.create_client(srv, name)
        if not client.wait_for_service(timeout_sec=call.timeout):
            raise TimeoutError(f"service {name} ({type_name}) is not available")
        request = fill(srv.Request(), call.params, f"{call.module.name} request")
        future = client.call_async(request)
        done = threading.Event()
        future.add_done_callback(lambda _f: done.set())
        if not done.wait(call.timeout):
            client.remove_pending_request(future)
            raise TimeoutError(f"service {name} did not answer within {call.timeout}s")
        response = to_dict(future.result())
        if response.get("success") is False:
            raise ModuleFailed(f"service {name} answered success=false: {response.get('message', '')}")
        return response

    def _publish(self, call: Call) -> dict[str, Any]:
        name, type_name = call.module.options["topic"], call.module.options["type"]
        msg_type = import_type(type_name)
        with self._lock:
            publisher = self._publishers.get((name, type_name))
            if publisher is None:
                publisher = self._publishers[(name, type_name)] = self.node.create_publisher(msg_type, name, 10)
        publisher.publish(fill(msg_type(), call.params, f"{call.module.name} message"))
        return {"published": name}

    def close(self) -> None:
        self._executor.shutdown()
        self._thread.join(timeout=5)
        self.node.destroy_node()
        if self._owns_context:
            self._rclpy.try_shutdown()
