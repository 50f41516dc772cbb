"""One ROS 2 context + a background executor thread: the only way the gateway runs rclpy.

Why: service calls must be made while an executor spins in another thread (a blocking call on the
executor's own thread deadlocks), and the executor must be shut down and joined before exit or the
process aborts. Each runtime has its own Context, so tests and the demo can run several in one
process, each on its chosen ROS_DOMAIN_ID. Shutdown is explicit (no SIGKILL: it leaks /dev/shm).
"""

from __future__ import annotations

import logging
import os
import threading

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

log = logging.getLogger(__name__)


def ros_env_defaults() -> None:
    """Loopback-only discovery unless the operator chose otherwise (see docs/ros.md)."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")


class RosRuntime:
    """``with RosRuntime() as rt: rt.add(node)`` — spins in a daemon thread, cleans up on exit."""

    def __init__(self, args: list[str] | None = None, domain_id: int | None = None, threads: int = 2) -> None:
        ros_env_defaults()
        self.context = Context()
        rclpy.init(args=args, context=self.context, domain_id=domain_id,
                   signal_handler_options=SignalHandlerOptions.NO)
        self.executor = MultiThreadedExecutor(num_threads=threads, context=self.context)
        self.nodes: list[Node] = []
        self._thread = threading.Thread(target=self._spin, name="ros-executor", daemon=True)
        self._started = False

    def add(self, node: Node) -> Node:
        self.nodes.append(node)
        self.executor.add_node(node)
        if not self._started:
            self._started = True
            self._thread.start()
        return node

    def make(self, node_cls: type, *args: object, **kwargs: object) -> Node:
        """Create ``node_cls(*args, context=<this runtime's context>, **kwargs)`` and spin it."""
        return self.add(node_cls(*args, context=self.context, **kwargs))

    def _spin(self) -> None:
        try:
            self.executor.spin()
        except (ExternalShutdownException, KeyboardInterrupt):
            pass
        except Exception:  # pragma: no cover - logged, the owner decides what to do
            log.exception("ROS executor stopped")

    def shutdown(self) -> None:
        """Stop spinning, destroy nodes, shut the context down (idempotent)."""
        for node in self.nodes:
            stop = getattr(node, "stop", None)
            if stop:
                stop()
        self.executor.shutdown(timeout_sec=2.0)
        if self._started:
            self._thread.join(timeout=5.0)
        for node in self.nodes:
            try:
                node.destroy_node()
            except Exception:  # pragma: no cover
                log.exception("destroying %s", node.get_name())
        self.nodes.clear()
        self.context.try_shutdown()

    def __enter__(self) -> "RosRuntime":
        return self

    def __exit__(self, *exc: object) -> None:
        self.shutdown()
