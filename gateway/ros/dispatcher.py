"""Then-part actions → robot service calls, with a per-call timeout, a bounded retry and a record.

Why separate from ROS: which service a robot's action goes to, how often to retry and what gets
recorded is policy; the actual call is injected (``ServiceCaller``), so this is tested without ROS
and the ROS adapter (:class:`gateway.ros.node.RosServiceCaller`) stays a few lines.

Mapping: robot name → service namespace from config (pepper → /pepper), action module → service:
say → <ns>/speak (Speak), move → <ns>/move_to (MoveTo), gesture → <ns>/gesture (Gesture).
Each outcome is recorded in the Information State's ``actions`` with the ``decision_id`` of the
decision it carries out, and handed to listeners (the robots' positions, the demo's narration).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Any, Callable, Protocol

from gateway.store.store import ACTIONS

log = logging.getLogger(__name__)

SERVICES = {"say": ("speak", "printeps_interfaces/srv/Speak"),
            "move": ("move_to", "printeps_interfaces/srv/MoveTo"),
            "gesture": ("gesture", "printeps_interfaces/srv/Gesture")}
RETRYABLE = {"timeout", "no_service", "failed"}
Outcome = dict[str, Any]


class ServiceCaller(Protocol):
    def __call__(self, service: str, type_name: str, params: dict[str, Any], timeout_s: float) -> tuple[str, str]:
        """Call one robot service; returns (status, message), status in ok/failed/timeout/no_service."""
        ...


class ActionDispatcher:
    """Sends each action to its robot's service and records the outcome in the Information State."""

    def __init__(self, caller: ServiceCaller, robots: dict[str, str], *, timeout_s: float = 2.0,
                 retries: int = 2, store: Any = None, retry_pause_s: float = 0.05) -> None:
        self.caller = caller
        self.robots = robots
        self.timeout_s = timeout_s
        self.retries = retries
        self.store = store
        self.retry_pause_s = retry_pause_s
        self._listeners: list[Callable[[Outcome], None]] = []

    def add_listener(self, listener: Callable[[Outcome], None]) -> None:
        """``listener(outcome)`` after every dispatched action (errors are logged)."""
        self._listeners.append(listener)

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

    def dispatch(self, action: dict[str, Any], context: dict[str, Any] | None = None) -> Outcome:
        """Call the action's service (retrying up to ``retries`` times); return and record the outcome."""
        started = time.monotonic()
        service, type_name = self.service_for(action)
        attempts = 0
        if service is None:
            status, message = "unsupported", type_name
        else:
            while True:
                attempts += 1
                status, message = self.caller(service, type_name, action.get("params") or {}, self.timeout_s)
                if status == "ok" or status not in RETRYABLE or attempts > self.retries:
                    break
                log.warning("%s %s: %s (%s), retry %d/%d", type_name, service, status, message, attempts, self.retries)
                time.sleep(self.retry_pause_s)
        outcome = {"action": action, "service": service, "status": status, "message": message,
                   "attempts": attempts, "duration_ms": round((time.monotonic() - started) * 1000, 3),
                   **(context or {})}
        (log.info if status == "ok" else log.error)("action %s → %s: %s %s", action.get("module"), service,
                                                    status, message)
        if self.store is not None:
            self.store.record(ACTIONS, outcome, stored_type=f"printeps/Action/{status}", inserted_by="gateway_node")
        for listener in list(self._listeners):
            try:
                listener(outcome)
            except Exception:
                log.exception("action listener failed")
        return outcome


class DispatchWorker:
    """Takes the ``actions`` events of rule bindings (from the stream engine) and dispatches their
    actions in order on its own thread, so a slow robot never holds up the stream."""

    def __init__(self, dispatcher: ActionDispatcher, queue_size: int = 1000) -> None:
        self.dispatcher = dispatcher
        self.queue: queue.Queue[dict[str, Any] | None] = queue.Queue(maxsize=queue_size)
        self.stats = {"decisions": 0, "actions": 0, "failed": 0, "dropped": 0}
        self._thread = threading.Thread(target=self._work, name="action-dispatch", daemon=True)
        self._thread.start()

    def on_stream_event(self, event: dict[str, Any]) -> None:
        """A stream engine subscriber: queue an ``actions`` event meant for the robots."""
        if event.get("kind") != "actions" or not event.get("dispatch", True) or not event.get("actions"):
            return
        try:
            self.queue.put_nowait(event)
        except queue.Full:
            self.stats["dropped"] += 1
            log.error("action queue full: the actions of decision %s were not dispatched", event.get("decision_id"))

    def idle(self) -> bool:
        return self.queue.empty() and self.queue.unfinished_tasks == 0

    def _work(self) -> None:
        while True:
            event = self.queue.get()
            try:
                if event is None:
                    return
                self.stats["decisions"] += 1
                context = {"decision_id": event.get("decision_id"), "query": event.get("query"),
                           "ruleset": event.get("ruleset"), "window": event.get("window")}
                for action in event["actions"]:
                    outcome = self.dispatcher.dispatch(action, context)
                    self.stats["actions"] += 1
                    if outcome["status"] != "ok":
                        self.stats["failed"] += 1
            except Exception:
                log.exception("dispatching the actions of decision %s failed", event and event.get("decision_id"))
            finally:
                self.queue.task_done()

    def stop(self, timeout_s: float = 5.0) -> None:
        self.queue.put(None)
        self._thread.join(timeout=timeout_s)
