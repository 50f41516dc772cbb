"""Module kinds are pluggable adapters: each turns one step's parameters into an effect and an output.

Why adapters: the executor is plain Python and knows nothing about ROS, Drools or humans. The
gateway plugs in real adapters (rclpy service/topic calls, the rules engine, the ontology, a board
of manual tasks); tests and the simulator plug in ones that only record. Every adapter gets the
step's timeout and a ``cancelled`` event it should honour.
"""

from __future__ import annotations

import itertools
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

from gateway.workflow.model import Module


@dataclass
class Call:
    """One module call as an adapter sees it."""

    workflow: str
    run_id: str
    step_id: str
    module: Module
    params: dict[str, Any]
    actor: str | None
    timeout: float
    cancelled: threading.Event = field(default_factory=threading.Event)
    trial: bool = False  # a run of unsaved edits (the editor's "try"): its rule firings are no decisions


class ModuleFailed(RuntimeError):
    """An adapter reports that the module ran and failed (e.g. a service answered success=false)."""


class Adapter(Protocol):
    def call(self, call: Call) -> dict[str, Any]:
        """Perform the module; return its output (a JSON-like dict) or raise."""
        ...


class WaitAdapter:
    """``wait``: pause for ``seconds`` (the papers' timing changes, e.g. suggestion 5)."""

    def call(self, call: Call) -> dict[str, Any]:
        seconds = float(call.params.get("seconds", 0))
        if seconds > call.timeout:
            raise ModuleFailed(f"wait of {seconds}s is longer than the step timeout {call.timeout}s")
        call.cancelled.wait(seconds)
        return {"waited": seconds}


class SimulatedRobots:
    """``ros_service``/``ros_topic`` without ROS: record what the robots were asked to do.

    Used by unit tests and by a gateway started without ROS; the record is what the agile-loop
    tests compare before and after an edit.
    """

    def __init__(self) -> None:
        self.calls: list[dict[str, Any]] = []
        self._lock = threading.Lock()

    def call(self, call: Call) -> dict[str, Any]:
        target = call.module.options.get("service") or call.module.options.get("topic")
        entry = {"run_id": call.run_id, "step": call.step_id, "module": call.module.name,
                 "actor": call.actor, "target": target, "params": call.params}
        with self._lock:
            self.calls.append(entry)
        return {"success": True, "message": f"simulated {call.module.name}"}


class RulesAdapter:
    """``fire_rules``: fire a rule set in the gateway's engine (the papers' "fire business rules").

    ``facts`` come from the step parameters (a list of fact dicts, usually ``${...}`` from earlier
    steps). The output is the engine's FireResult as a dict: ``actions``, ``fired``, ``facts``.
    """

    def __init__(self, engine: Any) -> None:
        self.engine = engine

    def call(self, call: Call) -> dict[str, Any]:
        facts = call.params.get("facts", [])
        if isinstance(facts, dict):
            facts = [facts]
        if not isinstance(facts, list):
            raise ModuleFailed(f"'facts' must be a list of fact objects, got {type(facts).__name__}")
        ruleset = call.params.get("ruleset") or call.module.options["ruleset"]
        result = self.engine.fire(ruleset, facts, origin="workflow", correlation_id=f"{call.run_id}/{call.step_id}",
                                  context={"workflow": call.workflow, "run_id": call.run_id, "step": call.step_id},
                                  record=not call.trial)
        return result.to_dict() if hasattr(result, "to_dict") else dict(result)


class OntologyValueAdapter:
    """``ontology_value``: read one named value from the knowledge base (e.g. robot-human distance).

    ``lookup(name)`` is injected: the gateway passes the ontology service's value reader, so an
    edit to the ontology is seen by the next step that reads it.
    """

    def __init__(self, lookup: Callable[[str], Any]) -> None:
        self.lookup = lookup

    def call(self, call: Call) -> dict[str, Any]:
        name = call.params.get("name")
        if not name:
            raise ModuleFailed("ontology_value needs a 'name' parameter")
        value = self.lookup(str(name))
        if value is None and "default" in call.params:
            value = call.params["default"]
        if value is None:
            raise ModuleFailed(f"the ontology has no value named {name!r}")
        return {"name": name, "value": value}


class DialogueAdapter:
    """``dialogue``: Pepper talks with the customer at a table until the order is complete (the
    dialogue rules, :class:`gateway.dialogue.service.DialogueService`); the output is the order
    (``drink``, ``cups``, ``table``, ``decision_ids``...).

    ``conversation`` names the conversation (one per table); Pepper opens with ``opening``.
    ``customer_says``, a list of
    sentences, plays a simulated customer (the demo, tests); without it the step waits for what
    real customers say (REST turns, the ROS ``Utterance`` topic) within the step's timeout.
    """

    def __init__(self, dialogue: Any) -> None:
        self.dialogue = dialogue

    def call(self, call: Call) -> dict[str, Any]:
        conversation = str(call.params.get("conversation") or "")
        if not conversation:
            raise ModuleFailed("a dialogue step needs a 'conversation' (e.g. the table's id)")
        table = call.params.get("table")
        said = call.params.get("customer_says") or []
        if isinstance(said, str):
            said = [said]
        try:
            order = self.dialogue.take_order(conversation, table=str(table) if table else None,
                                             customer_says=[str(s) for s in said], timeout_s=call.timeout,
                                             opening=str(call.params.get("opening") or "") or None,
                                             cancelled=call.cancelled)
        except LookupError as exc:
            raise ModuleFailed(str(exc)) from None
        return order


@dataclass
class ManualTask:
    """A step for a human: shown on the workbench until someone marks it done (or it times out)."""

    id: str
    run_id: str
    workflow: str
    step_id: str
    actor: str | None
    prompt: str
    params: dict[str, Any]
    created: float = field(default_factory=time.time)
    result: dict[str, Any] | None = None
    done: threading.Event = field(default_factory=threading.Event, repr=False)

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "run_id": self.run_id, "workflow": self.workflow, "step_id": self.step_id,
                "actor": self.actor, "prompt": self.prompt, "params": self.params, "created": self.created}


class ManualBoard:
    """``manual``: human steps (serving, settling the bill). Waits for ``complete(task_id)``.

    With ``simulate=True`` humans are simulated: each task completes by itself after its
    ``sim_seconds`` parameter (default 0), as in the teahouse simulation.
    """

    def __init__(self, simulate: bool = False) -> None:
        self.simulate = simulate
        self._tasks: dict[str, ManualTask] = {}
        self._ids = itertools.count(1)
        self._lock = threading.Lock()

    def call(self, call: Call) -> dict[str, Any]:
        task = ManualTask(id=f"task-{next(self._ids)}", run_id=call.run_id, workflow=call.workflow,
                          step_id=call.step_id, actor=call.actor,
                          prompt=str(call.params.get("prompt", call.module.description or call.module.name)),
                          params=call.params)
        with self._lock:
            self._tasks[task.id] = task
        try:
            if self.simulate:
                call.cancelled.wait(min(float(call.params.get("sim_seconds", 0)), call.timeout))
                return {"done": True, "simulated": True, "task": task.id}
            if not task.done.wait(call.timeout) or call.cancelled.is_set():
                raise TimeoutError(f"nobody completed the manual step {task.prompt!r} in {call.timeout}s")
            return {"done": True, "task": task.id, **(task.result or {})}
        finally:
            with self._lock:
                self._tasks.pop(task.id, None)

    def pending(self) -> list[ManualTask]:
        with self._lock:
            return list(self._tasks.values())

    def complete(self, task_id: str, result: dict[str, Any] | None = None) -> bool:
        """Mark a task done; False when no such task is waiting."""
        with self._lock:
            task = self._tasks.get(task_id)
        if task is None:
            return False
        task.result = dict(result or {})
        task.done.set()
        return True
