"""Running a workflow: route -> services -> processes -> steps, with data passing between steps.

Why it looks like this: the papers' workflows are sequences (and branches) of modules. A run walks
the route's services in order; each step's parameters are templates filled from the run's variables
(``input``, every ``save``d output, ``last``); each module call goes to the adapter of its kind,
in a worker thread bounded by the step's timeout; a failure is handled per step (``fail`` the run,
``continue``, or ``retry`` n times). Every step is recorded through the injected recorder.
A ``fire_rules`` module with ``dispatch`` performs the rules' then-part actions through workflow
modules (the BRMS "executes modules in the then-part").
"""

from __future__ import annotations

import concurrent.futures
import logging
import threading
import time
import uuid
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from typing import Any, Mapping

from gateway.workflow import expr
from gateway.workflow.adapters import Adapter, Call
from gateway.workflow.model import BranchStep, ModuleStep, ProcessStep, SetStep, Step, Workflow
from gateway.workflow.recorder import MemoryRecorder, Recorder

log = logging.getLogger(__name__)


class StepFailed(RuntimeError):
    """A step failed and its policy is ``fail``: the run stops here."""

    def __init__(self, step_id: str, message: str) -> None:
        super().__init__(f"step {step_id}: {message}")
        self.step_id = step_id
        self.message = message


@dataclass
class StepRecord:
    """What happened at one step (one entry of a run's trace)."""

    step_id: str
    process: str
    type: str  # module | process | branch | set
    status: str  # ok | failed | timeout | skipped
    module: str | None = None
    kind: str | None = None
    actor: str | None = None
    params: dict[str, Any] = field(default_factory=dict)
    output: Any = None
    error: str | None = None
    attempts: int = 1
    via: str | None = None  # the fire_rules step whose action this was
    started_at: str = ""
    duration_ms: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class RunResult:
    run_id: str
    workflow: str
    version: int | None
    status: str  # succeeded | failed
    steps: list[StepRecord]
    variables: dict[str, Any]
    error: str | None
    started_at: str
    duration_ms: float

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        data["steps"] = [s.to_dict() for s in self.steps]
        return data

    def actions(self) -> list[dict[str, Any]]:
        """The robot/human module calls of the run, in order: what the customers experienced."""
        return [{"step": s.step_id, "module": s.module, "kind": s.kind, "actor": s.actor, "params": s.params}
                for s in self.steps if s.type == "module" and s.kind in ("ros_service", "ros_topic", "manual")
                and s.status == "ok"]


class _Run:
    """The state of one run: its variables and its trace."""

    def __init__(self, workflow: Workflow, run_id: str, inputs: Mapping[str, Any], trial: bool = False) -> None:
        self.workflow = workflow
        self.run_id = run_id
        self.trial = trial
        self.variables: dict[str, Any] = {"input": {**workflow.inputs, **dict(inputs)}, "last": None}
        self.steps: list[StepRecord] = []
        self.cancelled = threading.Event()


class Executor:
    """Runs workflows with the given adapters (by module kind) and recorder."""

    def __init__(self, adapters: Mapping[str, Adapter], recorder: Recorder | None = None,
                 default_timeout: float = 10.0, max_workers: int = 8) -> None:
        self.adapters = dict(adapters)
        self.recorder = recorder or MemoryRecorder()
        self.default_timeout = default_timeout
        self._pool = concurrent.futures.ThreadPoolExecutor(max_workers=max_workers,
                                                           thread_name_prefix="workflow-step")

    def close(self) -> None:
        self._pool.shutdown(wait=False, cancel_futures=True)

    def run(self, workflow: Workflow, inputs: Mapping[str, Any] | None = None, *,
            version: int | None = None, run_id: str | None = None, trial: bool = False) -> RunResult:
        """Run the whole route once; never raises for step failures (see ``status``/``error``).
        ``trial``: the editor's "try my edits" — rule firings in it are no decisions."""
        run = _Run(workflow, run_id or uuid.uuid4().hex[:12], inputs or {}, trial)
        started_at = _now()
        t0 = time.perf_counter()
        self._record("workflow_run_started", {"run_id": run.run_id, "workflow": workflow.name,
                                              "version": version, "inputs": run.variables["input"],
                                              "at": started_at})
        error = None
        try:
            for service_name in workflow.route.services:
                for process_name in workflow.services[service_name].processes:
                    self._run_process(run, process_name)
        except StepFailed as exc:
            error = str(exc)
        except expr.ExpressionError as exc:  # raised outside a step (should not happen) — still a clean failure
            error = str(exc)
        finally:
            run.cancelled.set()
        result = RunResult(run_id=run.run_id, workflow=workflow.name, version=version,
                           status="failed" if error else "succeeded", steps=run.steps,
                           variables={k: v for k, v in run.variables.items()}, error=error,
                           started_at=started_at, duration_ms=(time.perf_counter() - t0) * 1e3)
        self._record("workflow_run_finished", {"run_id": run.run_id, "workflow": workflow.name, "version": version,
                                               "status": result.status, "error": error,
                                               "steps": len(run.steps), "duration_ms": result.duration_ms})
        return result

    # ------------------------------------------------------------ steps

    def _run_process(self, run: _Run, process_name: str) -> Any:
        last = None
        for step in run.workflow.processes[process_name].steps:
            last = self._run_step(run, process_name, step)
        return last

    def _run_steps(self, run: _Run, process_name: str, steps: tuple[Step, ...]) -> None:
        for step in steps:
            self._run_step(run, process_name, step)

    def _run_step(self, run: _Run, process_name: str, step: Step) -> Any:
        if isinstance(step, ModuleStep):
            return self._module_step(run, process_name, step)
        if isinstance(step, ProcessStep):
            return self._process_step(run, process_name, step)
        if isinstance(step, BranchStep):
            return self._branch_step(run, process_name, step)
        return self._set_step(run, process_name, step)

    def _set_step(self, run: _Run, process_name: str, step: SetStep) -> Any:
        record = StepRecord(step.id, process_name, "set", "ok", started_at=_now())
        try:
            values = expr.render(step.values, run.variables)
        except expr.ExpressionError as exc:
            return self._fail(run, record, str(exc), "fail")
        run.variables.update(values)
        record.output = values
        self._finish(run, record)
        return values

    def _branch_step(self, run: _Run, process_name: str, step: BranchStep) -> Any:
        record = StepRecord(step.id, process_name, "branch", "ok", started_at=_now())
        try:
            taken = bool(expr.evaluate(step.condition, run.variables))
        except expr.ExpressionError as exc:
            return self._fail(run, record, str(exc), "fail")
        record.output = {"condition": step.condition, "taken": "then" if taken else "else"}
        self._finish(run, record)
        self._run_steps(run, process_name, step.then if taken else step.otherwise)
        return run.variables.get("last")

    def _process_step(self, run: _Run, process_name: str, step: ProcessStep) -> Any:
        record = StepRecord(step.id, process_name, "process", "ok", started_at=_now())
        try:
            params = expr.render(step.params, run.variables)
        except expr.ExpressionError as exc:
            return self._fail(run, record, str(exc), step.on_failure)
        run.variables.update(params)
        record.params = params
        self._finish(run, record)
        try:
            output = self._run_process(run, step.process)
        except StepFailed:
            if step.on_failure != "continue":
                raise
            output = None
        if step.save:
            run.variables[step.save] = output
        return output

    def _module_step(self, run: _Run, process_name: str, step: ModuleStep, *,
                     params: dict[str, Any] | None = None, via: str | None = None,
                     step_id: str | None = None) -> Any:
        wf = run.workflow
        module = wf.modules[step.module]
        record = StepRecord(step_id or step.id, process_name, "module", "ok", module=module.name, kind=module.kind,
                            actor=wf.step_actor(step), via=via, started_at=_now())
        try:
            if params is None:
                rendered = expr.render({**module.params, **step.params}, run.variables)
            else:  # rule actions' parameters are data, not templates
                rendered = {**expr.render(module.params, run.variables), **params}
        except expr.ExpressionError as exc:
            return self._fail(run, record, str(exc), step.on_failure)
        record.params = rendered
        timeout = step.timeout or module.timeout or self.default_timeout
        attempts = 1 + ((step.retries or 1) if step.on_failure == "retry" else 0)
        t0 = time.perf_counter()
        for attempt in range(1, attempts + 1):
            record.attempts = attempt
            try:
                output = self._call(run, record, module, rendered, timeout)
                break
            except concurrent.futures.TimeoutError:
                record.status, record.error = "timeout", f"no answer within {timeout}s"
            except Exception as exc:  # any adapter failure is this step's failure, handled by policy
                record.status, record.error = "failed", f"{type(exc).__name__}: {exc}"
        else:
            record.duration_ms = (time.perf_counter() - t0) * 1e3
            return self._fail(run, record, record.error or "failed", step.on_failure, keep_status=True,
                              save=step.save)
        record.status, record.error = "ok", None
        record.output = output
        record.duration_ms = (time.perf_counter() - t0) * 1e3
        self._finish(run, record)
        run.variables["last"] = output
        if step.save:
            run.variables[step.save] = output
        dispatch = module.options.get("dispatch")
        if module.kind == "fire_rules" and dispatch and via is None:
            self._dispatch(run, process_name, record.step_id, output, dispatch, step.on_failure)
            run.variables["last"] = output
        return output

    def _dispatch(self, run: _Run, process_name: str, step_id: str, output: Any,
                  dispatch: Mapping[str, str], on_failure: str) -> None:
        """Perform the rules' then-part actions through the workflow modules mapped to them."""
        actions = output.get("actions", []) if isinstance(output, dict) else []
        for index, action in enumerate(actions, start=1):
            target = dispatch.get(str(action.get("module")))
            if target is None:
                continue
            sub = ModuleStep(id=f"{step_id}.{index}", module=target, on_failure=on_failure)
            self._module_step(run, process_name, sub, params=dict(action.get("params") or {}), via=step_id)

    def _call(self, run: _Run, record: StepRecord, module: Any, params: dict[str, Any],
              timeout: float) -> dict[str, Any]:
        adapter = self.adapters.get(module.kind)
        if adapter is None:
            raise LookupError(f"no adapter for module kind {module.kind!r} in this gateway")
        call = Call(workflow=run.workflow.name, run_id=run.run_id, step_id=record.step_id, module=module,
                    params=params, actor=record.actor, timeout=timeout, trial=run.trial)
        future = self._pool.submit(adapter.call, call)
        try:
            return future.result(timeout=timeout)
        except concurrent.futures.TimeoutError:
            call.cancelled.set()
            raise

    # ------------------------------------------------------------ bookkeeping

    def _fail(self, run: _Run, record: StepRecord, message: str, policy: str, *, keep_status: bool = False,
              save: str | None = None) -> Any:
        if not keep_status:
            record.status = "failed"
        record.error = message
        self._finish(run, record)
        if policy == "continue":
            failure = {"error": message, "status": record.status}
            run.variables["last"] = failure
            if save:
                run.variables[save] = failure
            return failure
        raise StepFailed(record.step_id, message)

    def _finish(self, run: _Run, record: StepRecord) -> None:
        run.steps.append(record)
        self._record("workflow_step", {"run_id": run.run_id, "workflow": run.workflow.name, **record.to_dict()})

    def _record(self, kind: str, payload: dict[str, Any]) -> None:
        try:
            self.recorder.record(kind, payload)
        except Exception:  # recording must never break a run
            log.warning("recording %s failed", kind, exc_info=True)


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")
