"""Robot actions → robot service calls, with a per-call timeout and a bounded retry.

Why separate from ROS: which service a robot's action goes to and how often to retry is policy;
the actual call is injected (``ServiceCaller``), so this is tested without ROS and the ROS adapter
(:class:`gateway.ros.node.RosServiceCaller`) stays a few lines. The dispatcher is the handler of
the robot modules in the gateway's action registry (:mod:`gateway.runtime.actions`), which records every
outcome with its decision.

Mapping: robot name → service namespace from config (pepper → /pepper), action module → service:
say → <ns>/speak (Speak), move → <ns>/move_to (MoveTo), gesture → <ns>/gesture (Gesture).
"""

from __future__ import annotations

import logging
import time
from typing import Any, Protocol

log = logging.getLogger(__name__)

SERVICES = {"say": ("speak", "printeps_interfaces/srv/Speak"),
            "move": ("move_to", "printeps_interfaces/srv/MoveTo"),
            "gesture": ("gesture", "printeps_interfaces/srv/Gesture")}
RETRYABLE = {"timeout", "no_service", "failed"}


class ServiceCaller(Protocol):
    def __call__(self, service: str, type_name: str, params: dict[str, Any], timeout_s: float) -> tuple[str, str]:
        """Call one robot service; returns (status, message), status in ok/failed/timeout/no_service."""
        ...


class ActionDispatcher:
    """Sends a robot action to its robot's service, retrying a bounded number of times."""

    modules = tuple(SERVICES)

    def __init__(self, caller: ServiceCaller, robots: dict[str, str], *, timeout_s: float = 2.0,
                 retries: int = 2, retry_pause_s: float = 0.05) -> None:
        self.caller = caller
        self.robots = robots
        self.timeout_s = timeout_s
        self.retries = retries
        self.retry_pause_s = retry_pause_s

    def service_for(self, action: dict[str, Any]) -> tuple[str, str] | tuple[None, str]:
        """(service name, type name) or (None, reason) when the action has no robot service."""
        module = action.get("module")
        robot = (action.get("params") or {}).get("robot")
        if module not in SERVICES:
            return None, f"module {module!r} has no robot service (known: {', '.join(SERVICES)})"
        if robot not in self.robots:
            return None, f"robot {robot!r} is not configured (ros.robots: {', '.join(self.robots) or 'none'})"
        suffix, type_name = SERVICES[module]
        return f"{self.robots[robot].rstrip('/')}/{suffix}", type_name

    def dispatch(self, action: dict[str, Any], context: dict[str, Any] | None = None) -> dict[str, Any]:
        """Call the action's service (retrying up to ``retries`` times): ``{"service", "status",
        "message", "attempts"}`` (an action handler of :class:`gateway.runtime.actions.ActionRouter`)."""
        service, type_name = self.service_for(action)
        attempts = 0
        if service is None:
            return {"service": None, "status": "unsupported", "message": type_name, "attempts": 0}
        while True:
            attempts += 1
            status, message = self.caller(service, type_name, action.get("params") or {}, self.timeout_s)
            if status == "ok" or status not in RETRYABLE or attempts > self.retries:
                break
            log.warning("%s %s: %s (%s), retry %d/%d", type_name, service, status, message, attempts, self.retries)
            time.sleep(self.retry_pause_s)
        return {"service": service, "status": status, "message": message, "attempts": attempts}
