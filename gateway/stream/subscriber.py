"""The rule-binding subscriber: a window's rows fired into the binding's rule set, outside the stream lock.

Why apart from the scheduler: a rule set's fire is a JVM call that may take long (a big session, a
slow then-part). Under the stream lock it would hold up every query, every sensor message and the
ROS callbacks behind them. So the work is cut in two:

- :meth:`BindingSubscriber.prepare` (under the stream lock, in window order) turns a window's
  rows into the binding's facts — ``suppress_repeats`` state and context providers included —
  and returns a :class:`PreparedFire`;
- :meth:`BindingSubscriber.deliver` (after the lock is released) hands the prepared fires to each
  binding's bulkhead (:class:`~gateway.stream.binding_fire.BindingFirer`: at most one fire in
  flight and one waiting, a newer window replaces the waiting one and is reported ``skipped``).
  Passes deliver in the order they were evaluated (a ticket taken under the lock), so a binding
  sees its windows in order even when two threads push at once.

Every fire is recorded as a decision through the rules engine's one recorder
(:func:`window_decision` says what the stream knows of it) and published as an ``actions`` event.

A stateful binding's session is a durable session of the rules engine's session manager
(:mod:`gateway.engine.sessions`) under a stable id, :func:`binding_session_id` (``stream.<query>``):
each window's fire is one command batch (clock to the window's instant, insert, fire) journalled
before it is answered, snapshotted like a REST session's, rebuilt after a restart and taken over
from a dead process on the binding's next fire. The session lives with its binding: removing the
binding disposes it (its log goes); a process that stops puts it away (its log stays).
"""

from __future__ import annotations

import logging
import re
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from gateway.config import StreamSettings
from gateway.engine.durable import Rebuilding
from gateway.engine.results import FireResult
from gateway.engine.sessions import SessionElsewhere
from gateway.stream.binding_fire import BindingFirer, Job
from gateway.stream.evaluate import WindowData
from gateway.stream.query_state import QueryRuntime
from gateway.stream.results import Row, triples_as_facts
from gateway.stream.rules import BindingError, RuleBinding, binding_facts

log = logging.getLogger(__name__)

Publish = Callable[[dict[str, Any]], None]


@dataclass
class PreparedFire:
    """One window's fire, ready to be handed to its binding."""

    runtime: QueryRuntime
    binding: RuleBinding
    firer: BindingFirer | None  # None: fired inline (a replay's scratch engine)
    facts: list[dict[str, Any]]
    instant: int
    window: dict[str, int]


def binding_session_id(query: str) -> str:
    """The stable id of a stateful binding's session: the same in every process and after a restart."""
    return "stream." + re.sub(r"[^A-Za-z0-9_.:-]", "_", query)[:120]


def same_session(old: RuleBinding | None, new: RuleBinding | None) -> bool:
    """Whether a binding replaced by ``new`` keeps its session (stateful both, the same rule set)."""
    return (old is not None and new is not None and old.mode == new.mode == "stateful"
            and old.ruleset == new.ruleset)


def window_decision(query: str, window: dict[str, int], session_id: str | None = None) -> dict[str, Any]:
    """What the stream knows of one binding fire's decision, passed to the engine's one recorder:
    its correlation id and context (a stateful one names its session: not replayable alone)."""
    context: dict[str, Any] = {"query": query, "window": window}
    if session_id is not None:
        context["session"] = session_id
    return {"origin": "stream", "correlation_id": f"{query}@{window['end']}", "context": context}


class BindingSubscriber:
    """Prepares, delivers, fires and reports the rule bindings' windows of one stream engine."""

    def __init__(self, settings: StreamSettings, rules_engine: Any, providers: dict[str, Any], publish: Publish,
                 publish_lock: threading.RLock) -> None:
        self.settings = settings
        self.rules_engine = rules_engine
        self.providers = providers
        self.publish = publish
        self._publish_lock = publish_lock  # counters and events of late fires, with the engine's publishing
        self.inline = False  # a replay's scratch engine fires on the pushing thread, in window order
        self._turn = threading.Condition()
        self._tickets = 0
        self._serving = 0

    # -- under the stream lock -----------------------------------------------------------------------
    def prepare(self, runtime: QueryRuntime, rows: list[Row], data: WindowData, instant: int) -> PreparedFire | None:
        """The binding's facts for this window's reported rows (None: nothing to fire)."""
        binding = runtime.binding
        if binding is None or not rows or runtime.query.form not in ("SELECT", "CONSTRUCT"):
            return None
        if runtime.query.form == "CONSTRUCT":
            rows = triples_as_facts(rows)
        try:
            facts = binding_facts(binding, rows, runtime.field_types, data, self.providers, runtime.handled)
        except Exception as exc:
            self._rule_error(runtime, binding, exc)
            return None
        if not facts:
            return None  # every row was a repeat: nothing new to decide
        if not self.inline and runtime.firer is None:
            runtime.firer = BindingFirer(runtime.query.name, self.settings.binding_wait_s)
        return PreparedFire(runtime, binding, None if self.inline else runtime.firer, facts, instant,
                            {"start": data.start_ms, "end": data.end_ms})

    def ticket(self) -> int:
        """A pass's place in the delivery order (taken under the stream lock)."""
        with self._turn:
            self._tickets += 1
            return self._tickets - 1

    def stop(self, runtime: QueryRuntime, keep: bool = False) -> None:
        """Stops the binding's thread (after its fire in flight) and closes its session: disposed
        (its log deleted: the binding is gone), or with ``keep`` put away (its log stays: the
        process stops, or the binding is replaced by one that keeps the session)."""
        if runtime.firer is not None:
            runtime.firer.close()
            runtime.firer = None
        session, runtime.session = runtime.session, None
        manager = getattr(self.rules_engine, "session_manager", None)
        binding = runtime.binding
        if manager is not None and binding is not None and binding.mode == "stateful":
            # by its id: the live session may be one a REST read rebuilt here, not the one the binding held
            session = manager.find(binding.ruleset, binding_session_id(runtime.query.name)) or session
        if session is None:
            return
        try:
            if keep and manager is not None:
                manager.put_away(session.ruleset, session.id)
            else:
                session.close()
        except Exception:  # closing a dead session must not hide the real work
            log.debug("closing the session of a stream binding failed", exc_info=True)

    # -- after the stream lock -----------------------------------------------------------------------
    def deliver(self, ticket: int, fires: list[PreparedFire]) -> None:
        """Hands a pass's fires to their bindings, once every earlier pass has handed over its own."""
        with self._turn:
            while self._serving != ticket:
                self._turn.wait()
        try:
            for fire in fires:
                self._deliver_one(fire)
        finally:
            with self._turn:
                self._serving += 1
                self._turn.notify_all()

    def _deliver_one(self, fire: PreparedFire) -> None:
        runtime, binding = fire.runtime, fire.binding
        if fire.firer is None:
            try:
                result = self._fire(fire)
            except Exception as exc:
                self._rule_error(runtime, binding, exc)
                return
            self._publish_actions(fire, result)
            return
        job = Job(lambda: self._fire(fire), lambda result, error: self._late(fire, result, error),
                  lambda: self._skipped(runtime, binding, fire.window))
        try:
            done, result = fire.firer.fire(job)
        except Exception as exc:
            self._rule_error(runtime, binding, exc)
            return
        if done:
            self._publish_actions(fire, result)

    def _fire(self, fire: PreparedFire) -> Any:
        """One window's fire, on the binding's thread (a stateful binding's session is used by it alone)."""
        runtime, binding, window = fire.runtime, fire.binding, fire.window
        name = runtime.query.name
        if binding.mode == "stateful":
            session = self._session(runtime, binding)
            return _push(self.rules_engine.recorder, session, fire.facts, fire.instant,
                         window_decision(name, window, session.id))
        return self.rules_engine.fire(binding.ruleset, fire.facts, **window_decision(name, window))

    def _session(self, runtime: QueryRuntime, binding: RuleBinding) -> Any:
        """The binding's session: this process's, rebuilt from its log, or opened (on first use)."""
        if runtime.session is not None and not runtime.session.closed:
            return runtime.session
        if runtime.binding is not binding:  # unbound meanwhile: open no session for it
            raise BindingError(f"the binding of {runtime.query.name!r} to {binding.ruleset!r} was removed")
        manager = getattr(self.rules_engine, "session_manager", None)
        if manager is None:  # a rules engine without a session registry (a test's)
            runtime.session = self.rules_engine.open_session(binding.ruleset, on_deploy=binding.on_deploy)
            return runtime.session
        session_id = binding_session_id(runtime.query.name)
        try:
            runtime.session = _rebuilt(manager, binding, session_id)
        except SessionElsewhere as exc:
            raise BindingError(f"the session {session_id} of {binding.ruleset!r} is held by gateway process "
                               f"{exc.owner.get('process')}: a stateful binding fires in one process; send the "
                               "stream's messages to that one (docs/streams.md)") from None
        return runtime.session

    # -- reporting -----------------------------------------------------------------------------------
    def _publish_actions(self, fire: PreparedFire, result: Any, late: bool = False) -> None:
        payload = result.to_dict() if hasattr(result, "to_dict") else dict(result)
        event = {
            "kind": "actions", "query": fire.runtime.query.name, "ruleset": fire.binding.ruleset,
            "version": payload.get("version"), "decision_id": payload.get("decision_id"), "window": fire.window,
            "facts": fire.facts, "actions": payload.get("actions", []), "fired": payload.get("fired", []),
            "dispatch": fire.binding.dispatch,
        }
        if late:
            event["late"] = True
        with self._publish_lock:
            fire.runtime.stats["rule_fires"] += 1
            self.publish(event)

    def _late(self, fire: PreparedFire, result: Any, error: BaseException | None) -> None:
        """A fire that outlasted ``streams.binding_wait_s`` (or waited behind one) reports itself."""
        with self._publish_lock:
            fire.runtime.stats["rule_late"] += 1
            if error is not None:
                self._rule_error(fire.runtime, fire.binding, error)
            else:
                self._publish_actions(fire, result, late=True)

    def _skipped(self, runtime: QueryRuntime, binding: RuleBinding, window: dict[str, int]) -> None:
        """A window replaced by a newer one while the binding's fire was in flight: said, not silent."""
        with self._publish_lock:
            runtime.stats["rule_skipped"] += 1
            self.publish({"kind": "skipped", "query": runtime.query.name, "ruleset": binding.ruleset, "window": window,
                          "reason": f"the rules of {binding.ruleset!r} were still firing an earlier window; "
                                    "a newer window replaced this one (streams.binding_wait_s)"})

    def _rule_error(self, runtime: QueryRuntime, binding: RuleBinding, exc: BaseException) -> None:
        name = runtime.query.name
        log.warning("query %s: firing %s failed: %s", name, binding.ruleset, exc)
        with self._publish_lock:
            runtime.stats["rule_errors"] += 1
            runtime.last_error = f"rules {binding.ruleset!r}: {exc}"
            self.publish({"kind": "error", "query": name, "error": runtime.last_error})



def _rebuilt(manager: Any, binding: RuleBinding, session_id: str) -> Any:
    """The binding's session from the session manager, waiting (on the binding's thread, newer
    windows coalescing meanwhile) while it is being rebuilt, up to ``sessions.rebuild_timeout_s``:
    a window is not lost to a rebuild that a REST read started a moment before."""
    deadline = time.monotonic() + float(getattr(manager.settings, "rebuild_timeout_s", 30.0))
    while True:
        try:
            return manager.binding_session(binding.ruleset, session_id, on_deploy=binding.on_deploy)
        except Rebuilding as exc:
            if time.monotonic() > deadline:
                raise
            time.sleep(min(max(float(exc.retry_after_s), 0.05), 1.0))


def _push(recorder: Any, session: Any, facts: list[dict[str, Any]], instant: int,
          decision: dict[str, Any]) -> FireResult:
    """Insert stamped with the window's instant (the clock moves there first, never back), fire,
    and record the decision. A durable session takes it as one command batch, journalled before it
    is answered; any other in one JVM call through the session's buffers."""
    if getattr(session, "durability", None) is None:
        result = session.push(facts, instant)
        recorder.record(result, facts, **decision)
        return result
    started = time.perf_counter()
    commands = [{"op": "advance_to", "to": int(instant)}, {"op": "insert", "facts": facts, "ret": False},
                {"op": "fire", "max": -1}]
    answer = session.execute(commands)
    return recorder.session_fire(session.ruleset, commands, answer,
                                 duration_ms=(time.perf_counter() - started) * 1000, **decision)
