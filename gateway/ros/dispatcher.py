"""Then-part actions → robot service calls, with a per-call timeout, a bounded retry and a record.

Why separate from ROS: which service a robot's action goes to, how often to retry and what gets
recorded is policy; the actual call is injected (``ServiceCaller``), so this is tested without ROS
and the ROS adapter (gateway.ros.node.RosServiceCaller) stays a few lines.

Mapping: robot name → service namespace from config (pepper → /pepper), action module → service:
say → <ns>/speak (Speak), move → <ns>/move_to (MoveTo), gesture → <ns>/gesture (Gesture).
"""

from __future__ import annotations

import logging
import time
from typing import Any, Callable, Protocol

from gateway.store.store import ACTIONS

log = logging.getLogger(__name__)

SERVICES = {"say": ("speak", "Speak"), "move": ("move_to", "MoveTo"), "gesture": ("gesture", "Gesture")}
RETRYABLE = {"timeout", "no_service", "failed"}


class ServiceCaller(Protocol):
    def __call__(self, service: str, kind: str, params: dict[str, Any], timeout_s: float) -> tuple[str, str]:
        """Call one robot service; returns (status, message), status in ok/failed/timeout/no_service."""
        ...


class ActionDispatcher:
    """Sends each action to its robot's service and records the outcome in the Information State."""

    def __init__(self, caller: ServiceCaller, robots: dict[str, str], *, timeout_s: float = 2.0,
                 retries: int = 2, store: Any = None, retry_pause_s: float = 0.05,
                 on_outcome: Callable[[dict[str, Any]], None] | None = None) -> None:
        self.caller = caller
        self.robots = robots
        self.timeout_s = timeout_s
        self.retries = retries
        self.store = store
        self.retry_pause_s = retry_pause_s
        self.on_outcome = on_outcome
        # set by the Pipeline so action records join its per-reading batch (written after the reading)
        self.record: Callable[[str, dict[str, Any], str], None] | None = None

    def service_for(self, action: dict[str, Any]) -> tuple[str, str] | tuple[None, str]:
        """(service name, kind) or (None, reason) when the action has no robot service."""
        module = action.get("module")
        robot = (action.get("params") or {}).get("robot")
        if module not in SERVICES:
            return None, f"module {module!r} has no robot service (known: {', '.join(SERVICES)})"
        if robot not in self.robots:
            return None, f"robot {robot!r} is not configured (ros.robots: {', '.join(self.robots) or 'none'})"
        suffix, kind = SERVICES[module]
        return f"{self.robots[robot].rstrip('/')}/{suffix}", kind

    def dispatch(self, action: dict[str, Any], context: dict[str, Any] | None = None) -> dict[str, Any]:
        """Call the action's service (retrying up to ``retries`` times); return and record the outcome."""
        started = time.monotonic()
        service, kind = self.service_for(action)
        attempts = 0
        if service is None:
            status, message = "unsupported", kind
        else:
            while True:
                attempts += 1
                status, message = self.caller(service, kind, action.get("params") or {}, self.timeout_s)
                if status == "ok" or status not in RETRYABLE or attempts > self.retries:
                    break
                log.warning("%s %s: %s (%s), retry %d/%d", kind, service, status, message, attempts, self.retries)
                time.sleep(self.retry_pause_s)
        outcome = {"action": action, "service": service, "status": status, "message": message,
                   "attempts": attempts, "duration_ms": round((time.monotonic() - started) * 1000, 3),
                   **(context or {})}
        (log.info if status == "ok" else log.error)("action %s → %s: %s %s", action.get("module"), service,
                                                    status, message)
        if self.on_outcome:
            self.on_outcome(outcome)
        if self.record is not None:
            self.record(ACTIONS, outcome, f"printeps/Action/{status}")
        elif self.store is not None:
            self.store.record(ACTIONS, outcome, stored_type=f"printeps/Action/{status}", inserted_by="gateway_node")
        return outcome
