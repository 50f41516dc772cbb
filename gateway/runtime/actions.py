"""Then-part actions of decisions → what performs them: one action contract, one registry.

A rule's then-part asks for actions (``actions.say("pepper", "Welcome")``,
``actions.call("workflow", "name", "clear_table", "table", "table2")``): ``{"module", "params"}``.
When a stream-bound decision is made, its actions are performed here, in order, on one worker
thread (a slow robot never holds up the stream): each module name has a handler —
``say``/``move``/``gesture`` go to the robots' ROS services (registered by the ROS side when the
gateway runs one), ``workflow`` starts a workflow run. Every outcome — ``{"action", "status"
(ok/failed/timeout/no_service/unsupported), "message", ...}`` — is recorded in the Information
State's ``actions`` with the ``decision_id`` it carries out, and handed to listeners (the robots'
positions, the demo's narration, the live view).

Plain Python: handlers and the store are injected (cf. ansible-rulebook's action registry).
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Any, Callable

from gateway.base.logs import RepeatLimiter
from gateway.store.store import ACTIONS

log = logging.getLogger(__name__)

Outcome = dict[str, Any]
Handler = Callable[[dict[str, Any], dict[str, Any]], Outcome]  # (action, context) -> outcome fields


class ActionRouter:
    """Performs the actions of ``actions`` events (see the module docstring)."""

    def __init__(self, store: Any = None, queue_size: int = 1000) -> None:
        self.store = store
        self.handlers: dict[str, Handler] = {}
        self._listeners: list[Callable[[Outcome], None]] = []
        self.queue: queue.Queue[dict[str, Any] | None] = queue.Queue(maxsize=queue_size)
        self.stats = {"decisions": 0, "actions": 0, "failed": 0, "dropped": 0}
        self._repeats = RepeatLimiter()
        self._thread = threading.Thread(target=self._work, name="actions", daemon=True)
        self._thread.start()

    def register(self, module: str, handler: Handler) -> None:
        """``handler(action, context) -> {"status", "message", ...}`` performs ``module``."""
        self.handlers[module] = handler

    def add_listener(self, listener: Callable[[Outcome], None]) -> None:
        """``listener(outcome)`` after every performed action (errors are logged)."""
        self._listeners.append(listener)

    def on_stream_event(self, event: dict[str, Any]) -> None:
        """A stream engine subscriber: queue an ``actions`` event meant to be performed."""
        if event.get("kind") != "actions" or not event.get("dispatch", True) or not event.get("actions"):
            return
        try:
            self.queue.put_nowait(event)
        except queue.Full:
            self.stats["dropped"] += 1
            log.error("action queue full: the actions of decision %s were not performed", event.get("decision_id"))

    def idle(self) -> bool:
        return self.queue.empty() and self.queue.unfinished_tasks == 0

    def perform(self, action: dict[str, Any], context: dict[str, Any] | None = None) -> Outcome:
        """Perform one action now (on the caller's thread); record and announce the outcome."""
        started = time.monotonic()
        context = dict(context or {})
        handler = self.handlers.get(str(action.get("module")))
        if handler is None:
            fields: Outcome = {"status": "unsupported", "message": f"no handler for module {action.get('module')!r} "
                               f"on this gateway (known: {', '.join(sorted(self.handlers)) or 'none'})"}
        else:
            try:
                fields = handler(action, context)
            except Exception as exc:  # a broken handler is a failed action, never a dead worker
                log.exception("action %s failed", action.get("module"))
                fields = {"status": "failed", "message": f"{type(exc).__name__}: {exc}"}
        outcome = {"action": action, "attempts": 1, **fields,
                   "duration_ms": round((time.monotonic() - started) * 1000, 3), **context}
        self._log(outcome)
        if self.store is not None:
            self.store.record(ACTIONS, outcome, stored_type=f"printeps/Action/{outcome['status']}",
                              inserted_by="gateway")
        for listener in list(self._listeners):
            try:
                listener(outcome)
            except Exception:
                log.exception("action listener failed")
        return outcome

    def _log(self, outcome: Outcome) -> None:
        """One line per action; a failure that repeats (same module and status) at most once a
        minute, saying how many like it were not logged (every outcome is still recorded)."""
        module, status = outcome["action"].get("module"), outcome["status"]
        if status == "ok":
            log.info("action %s: ok %s", module, outcome.get("message", ""))
            return
        now, held = self._repeats.check((module, status))
        if now:
            log.error("action %s: %s %s%s", module, status, outcome.get("message", ""),
                      f" ({held} more like it in the last {self._repeats.window_s:g} s not logged)" if held else "")

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
                    outcome = self.perform(action, context)
                    self.stats["actions"] += 1
                    if outcome["status"] != "ok":
                        self.stats["failed"] += 1
            except Exception:
                log.exception("performing the actions of decision %s failed", event and event.get("decision_id"))
            finally:
                self.queue.task_done()

    def close(self, timeout_s: float = 5.0) -> None:
        """Finish what is queued (bounded), then stop."""
        self.queue.put(None)
        self._thread.join(timeout=timeout_s)


def workflow_handler(workflows: Any) -> Handler:
    """``workflow``: start the workflow ``params.name`` in the background with the other params as
    its inputs (``actions.call("workflow", "name", "clear_table", "table", "table2")``)."""

    def start(action: dict[str, Any], context: dict[str, Any]) -> Outcome:
        params = dict(action.get("params") or {})
        name = params.pop("name", None)
        if not name:
            return {"status": "failed", "message": "a workflow action needs a 'name' parameter"}
        try:
            run_id = workflows.start(str(name), params)
        except LookupError as exc:
            return {"status": "failed", "message": str(exc)}
        return {"status": "ok", "message": f"workflow {name} started", "run_id": run_id, "service": f"workflow/{name}"}

    return start
