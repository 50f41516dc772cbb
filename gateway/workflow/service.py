"""The gateway's workflow service: registry + executor + adapters + run history, wired from settings.

Why a separate module: the REST router, the CLI and tests need the same assembled object, and the
wiring (which adapter for which module kind, which recorder) is decided in one place:

- ``ros_service``/``ros_topic``: the gateway's ROS node (``gateway.workflow.ros``) when it runs
  one and robots are not simulated, else :class:`SimulatedRobots` (records the calls);
- ``fire_rules``: the gateway's engine; ``ontology_value``: the gateway's knowledge base
  (asserted and SWRL-inferred values, following every edit);
- ``manual``: a board of human tasks (simulated humans in the demo); ``wait``: sleeping.
Runs are recorded in the Information State (collection ``workflow_runs``) when a store is given.
"""

from __future__ import annotations

import collections
import logging
import threading
import uuid
from typing import Any, Callable, Mapping

from gateway.workflow.adapters import (
    Adapter, ManualBoard, OntologyValueAdapter, RulesAdapter, SimulatedRobots, WaitAdapter, DialogueAdapter)
from gateway.workflow.executor import Executor, RunResult
from gateway.workflow.loader import Problem, WorkflowInvalid, parse
from gateway.workflow.model import Workflow
from gateway.workflow.recorder import CallableRecorder, FanOutRecorder, MemoryRecorder, Recorder
from gateway.workflow.registry import WorkflowRegistry

log = logging.getLogger(__name__)

RUNS_COLLECTION = "workflow_runs"


class RealRobots(RuntimeError):
    """A trial run of unsaved edits was asked for where robots are real, not simulated."""


class WorkflowService:
    """What the API uses: read, validate, replace and run workflows; see runs and manual tasks."""

    def __init__(self, registry: WorkflowRegistry, executor: Executor, manual: ManualBoard,
                 robots: SimulatedRobots | None = None, runs_kept: int = 200,
                 recorder: MemoryRecorder | None = None) -> None:
        self.registry = registry
        self.executor = executor
        self.manual = manual
        self.robots = robots
        self.recorder = recorder
        self._runs: collections.OrderedDict[str, RunResult | None] = collections.OrderedDict()
        self._runs_kept = runs_kept
        self._lock = threading.Lock()

    def validate(self, text: str, file: str = "<edit>") -> tuple[Workflow | None, list[Problem]]:
        """Parse without deploying: (workflow, []) or (None, problems)."""
        try:
            return parse(text, file=file), []
        except WorkflowInvalid as exc:
            return None, exc.problems

    def run(self, name: str, inputs: Mapping[str, Any] | None = None, run_id: str | None = None) -> RunResult:
        """Run the current version of ``name`` to its end (the version is fixed at the start)."""
        entry = self.registry.current(name)
        run_id = run_id or uuid.uuid4().hex[:12]
        self._remember(run_id, None)
        result = self.executor.run(entry.workflow, inputs or {}, version=entry.info.version, run_id=run_id)
        self._remember(run_id, result)
        return result

    def start(self, name: str, inputs: Mapping[str, Any] | None = None) -> str:
        """Run in the background (for workflows with human steps); returns the run id at once."""
        self.registry.current(name)  # fail now if unknown
        run_id = uuid.uuid4().hex[:12]
        self._remember(run_id, None)
        threading.Thread(target=self._run_quietly, args=(name, inputs, run_id), daemon=True,
                         name=f"workflow-{name}-{run_id}").start()
        return run_id

    def try_text(self, text: str, inputs: Mapping[str, Any] | None = None) -> str:
        """Run an unsaved workflow text in the background on the simulated robots (the editor's
        "try my edits"); nothing is stored as a version. Returns the run id. Raises
        :class:`WorkflowInvalid`, or :class:`RealRobots` when robots are not simulated here."""
        if self.robots is None:
            raise RealRobots("this gateway drives real robots: save the workflow, then run it")
        workflow = parse(text, file="<try>")
        run_id = "try-" + uuid.uuid4().hex[:12]
        self._remember(run_id, None)

        def run() -> None:
            try:
                self._remember(run_id, self.executor.run(workflow, inputs or {}, version=None, run_id=run_id,
                                                             trial=True))
            except Exception:  # a background run has nobody to raise to: log it
                log.exception("trial run %s of %s crashed", run_id, workflow.name)

        threading.Thread(target=run, daemon=True, name=f"workflow-try-{run_id}").start()
        return run_id

    def _run_quietly(self, name: str, inputs: Mapping[str, Any] | None, run_id: str) -> None:
        try:
            self.run(name, inputs, run_id)
        except Exception:  # a background run has nobody to raise to: log it
            log.exception("workflow run %s of %s crashed", run_id, name)

    def running(self) -> int:
        """How many runs have not finished yet."""
        with self._lock:
            return sum(1 for r in self._runs.values() if r is None)

    def get_run(self, run_id: str) -> RunResult | None:
        """The result, or None while it is running; KeyError when unknown."""
        with self._lock:
            return self._runs[run_id]

    def steps_so_far(self, run_id: str) -> list[dict[str, Any]]:
        """The steps a run has done until now, in order (what the editor's trace shows while it runs)."""
        if self.recorder is None:
            return []
        return [step for step in self.recorder.of_kind("workflow_step") if step.get("run_id") == run_id]

    def runs(self, workflow: str | None = None, limit: int = 50) -> list[RunResult]:
        with self._lock:
            done = [r for r in self._runs.values() if r is not None and (workflow is None or r.workflow == workflow)]
        return list(reversed(done))[:limit]

    def _remember(self, run_id: str, result: RunResult | None) -> None:
        with self._lock:
            self._runs[run_id] = result
            self._runs.move_to_end(run_id)
            while len(self._runs) > self._runs_kept:
                self._runs.popitem(last=False)

    def close(self) -> None:
        self.executor.close()


def build_service(settings: Any, *, catalog: Any = None, engine: Any = None, store: Any = None,
                  ontology_lookup: Callable[[str], Any] | None = None,
                  ros_modules: Adapter | None = None, dialogue: Any = None) -> WorkflowService:
    """Assemble the service from ``settings.workflows`` and what the gateway runs: its catalog
    (versions), engine (``fire_rules``), knowledge (``ontology_value``), ROS node (robot modules;
    simulated robots without one) and Information State (runs recorded).

    The registry serves nothing yet: like the other catalog-backed services, the composition root
    seeds it from its folder and loads it (``registry.seed(folder)``, ``registry.load()``; see
    :mod:`gateway.base.lifecycle` and ``gateway.runtime.transfer.seed_folders``), so which folders
    seed a gateway is said in one place."""
    cfg = settings.workflows
    robots: SimulatedRobots | None = None
    adapters: dict[str, Adapter] = {"wait": WaitAdapter()}
    simulate = ros_modules is None if cfg.simulate_robots is None else cfg.simulate_robots
    if simulate or ros_modules is None:
        robots = SimulatedRobots()
        adapters["ros_service"] = adapters["ros_topic"] = robots
    else:
        adapters["ros_service"] = adapters["ros_topic"] = ros_modules
    if engine is not None:
        adapters["fire_rules"] = RulesAdapter(engine)
    if ontology_lookup is not None:
        adapters["ontology_value"] = OntologyValueAdapter(ontology_lookup)
    if dialogue is not None:
        adapters["dialogue"] = DialogueAdapter(dialogue)
    manual = ManualBoard(simulate=cfg.simulate_humans)
    adapters["manual"] = manual
    memory = MemoryRecorder()
    recorder: Recorder = memory
    if store is not None:
        def to_store(kind: str, payload: dict[str, Any]) -> None:
            store.record(RUNS_COLLECTION, payload, stored_type=f"printeps/{kind}", inserted_by="workflow_executor")

        recorder = FanOutRecorder(memory, CallableRecorder(to_store))
    executor = Executor(adapters, recorder, default_timeout=cfg.default_timeout_s)
    registry = WorkflowRegistry(catalog)
    return WorkflowService(registry, executor, manual, robots, runs_kept=cfg.runs_kept, recorder=memory)
