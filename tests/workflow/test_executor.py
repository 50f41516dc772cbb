"""The executor: data passing, branches, per-step timeouts and failure policies, rule actions, records."""

from __future__ import annotations

import threading
import time

from gateway.workflow.adapters import Call, ManualBoard, ModuleFailed, WaitAdapter
from gateway.workflow.executor import Executor
from gateway.workflow.loader import parse

FLAKY = """\
workflow: flaky
modules:
  flaky: {kind: ros_service, service: /flaky, type: std_srvs/srv/Trigger}
  slow: {kind: ros_service, service: /slow, type: std_srvs/srv/Trigger, timeout: 0.2}
  say: {kind: ros_service, service: /say, type: std_srvs/srv/Trigger}
processes:
  main:
    steps:
      - {id: first, module: flaky, on_failure: POLICY, retries: RETRIES, save: result}
      - {id: after, module: say, with: {text: "result was ${result}"}}
services:
  s: {processes: [main]}
route: {services: [s]}
"""


class Flaky:
    """Fails ``failures`` times, then answers; ``/slow`` never answers in time."""

    def __init__(self, failures: int) -> None:
        self.failures = failures
        self.calls: list[str] = []

    def call(self, call: Call) -> dict:
        self.calls.append(call.module.name)
        if call.module.name == "slow":
            call.cancelled.wait(5)
            return {"late": True}
        if call.module.name == "flaky" and self.failures > 0:
            self.failures -= 1
            raise ModuleFailed("robot busy")
        return {"success": True, "n": len(self.calls)}


def flaky(policy: str, retries: int = 0) -> str:
    text = FLAKY.replace("POLICY", policy)
    return text.replace(", retries: RETRIES", f", retries: {retries}" if retries else "")


def test_data_passes_between_steps_and_branches_follow_data(executor, robots, small):
    result = executor.run(parse(small))
    assert result.status == "succeeded", result.error
    texts = [c["params"]["text"] for c in robots.calls]
    assert texts == ["Welcome. Two seats?", "simulated say"]  # echo reads the saved output of step "two"
    result = executor.run(parse(small), {"customers": ["a", "b", "c"]})
    assert [c["params"]["text"] for c in robots.calls[2:]][0] == "Welcome. 3 seats?"
    assert result.status == "failed" and "said" in result.error  # 'said' was never saved on this path
    assert [s.step_id for s in result.steps] == ["greet_1", "choose", "other", "pause", "echo"]
    assert result.steps[-1].status == "failed"


def test_policy_fail_stops_the_run():
    adapter = Flaky(failures=1)
    ex = Executor({"ros_service": adapter})
    result = ex.run(parse(flaky("fail")))
    assert result.status == "failed" and "robot busy" in result.error
    assert adapter.calls == ["flaky"]
    ex.close()


def test_policy_continue_records_the_failure_and_goes_on():
    adapter = Flaky(failures=1)
    ex = Executor({"ros_service": adapter})
    result = ex.run(parse(flaky("continue")))
    assert result.status == "succeeded"
    assert [s.status for s in result.steps] == ["failed", "ok"]
    assert "robot busy" in result.steps[1].params["text"]  # the failure was saved for later steps
    ex.close()


def test_policy_retry():
    adapter = Flaky(failures=2)
    ex = Executor({"ros_service": adapter})
    result = ex.run(parse(flaky("retry", retries=2)))
    assert result.status == "succeeded" and result.steps[0].attempts == 3
    ex.close()
    ex = Executor({"ros_service": Flaky(failures=5)})
    result = ex.run(parse(flaky("retry", retries=2)))
    assert result.status == "failed" and result.steps[0].attempts == 3
    ex.close()


def test_step_timeout_is_bounded_and_cancels_the_call():
    adapter = Flaky(failures=0)
    ex = Executor({"ros_service": adapter})
    wf = parse(flaky("fail").replace("module: flaky", "module: slow"))
    t0 = time.monotonic()
    result = ex.run(wf)
    assert time.monotonic() - t0 < 4  # far below the adapter's 5 s: the step gave up at its timeout
    assert result.status == "failed" and result.steps[0].status == "timeout"
    assert "0.2s" in result.steps[0].error
    ex.close()


def test_missing_adapter_is_a_clear_step_failure(small):
    ex = Executor({})
    result = ex.run(parse(small))
    assert result.status == "failed" and "no adapter for module kind 'ros_service'" in result.error
    ex.close()


class StubEngine:
    def __init__(self) -> None:
        self.fired: list[tuple[str, list]] = []
        self.recorded: list[bool] = []

    def fire(self, ruleset: str, facts: list, **decision: object) -> dict:
        assert decision["origin"] == "workflow" and decision["correlation_id"]  # every fire is a decision
        self.recorded.append(bool(decision.get("record", True)))  # ...except in a trial of unsaved edits
        self.fired.append((ruleset, facts))
        return {"ruleset": ruleset, "version": 1, "fired": [], "facts": facts, "actions": [
            {"module": "say", "params": {"robot": "pepper", "text": "Welcome. ${not a template}"}},
            {"module": "gesture", "params": {"robot": "pepper", "name": "bow"}},
            {"module": "unknown_action", "params": {}},
        ]}


def test_fire_rules_then_part_actions_run_through_modules(robots, recorder):
    from gateway.workflow.adapters import RulesAdapter

    wf = parse("""\
workflow: rules
actors: {pepper: {kind: robot}}
modules:
  rules: {kind: fire_rules, ruleset: reception, dispatch: {say: say, gesture: gesture}}
  say: {kind: ros_service, actor: pepper, service: /pepper/speak, type: printeps_interfaces/srv/Speak}
  gesture: {kind: ros_service, actor: pepper, service: /pepper/gesture, type: printeps_interfaces/srv/Gesture}
processes:
  p:
    steps:
      - {id: fire, module: rules, with: {facts: "${[{'type': 'Customer', 'age': input.age}]}"}, save: decision}
      - {id: count, set: {actions: "${len(decision.actions)}"}}
services: {s: {processes: [p]}}
route: {services: [s]}
""")
    engine = StubEngine()
    ex = Executor({"fire_rules": RulesAdapter(engine), "ros_service": robots}, recorder)
    result = ex.run(wf, {"age": 30})
    assert result.status == "succeeded", result.error
    assert engine.fired == [("reception", [{"type": "Customer", "age": 30}])]
    assert [(c["module"], c["params"]) for c in robots.calls] == [
        ("say", {"robot": "pepper", "text": "Welcome. ${not a template}"}),  # action data is not templated
        ("gesture", {"robot": "pepper", "name": "bow"})]
    assert [s.step_id for s in result.steps] == ["fire", "fire.1", "fire.2", "count"]
    assert result.steps[1].via == "fire" and result.variables["actions"] == 3
    kinds = [kind for kind, _ in recorder.events]
    assert kinds[0] == "workflow_run_started" and kinds[-1] == "workflow_run_finished"
    assert kinds.count("workflow_step") == 4
    assert ex.run(wf, {"age": 31}, trial=True).status == "succeeded"  # the editor's "try my edits"
    assert engine.recorded == [True, False]


def test_manual_step_waits_for_a_human_and_times_out():
    board = ManualBoard(simulate=False)
    wf = parse("""\
workflow: human
actors: {staff: {kind: human}}
modules: {serve: {kind: manual, actor: staff, timeout: 5}}
processes: {p: {steps: [{id: serve, module: serve, with: {prompt: "Serve table ${input.table}"}, save: served}]}}
services: {s: {processes: [p]}}
route: {services: [s]}
""")
    ex = Executor({"manual": board})
    box: dict = {}
    runner = threading.Thread(target=lambda: box.setdefault("result", ex.run(wf, {"table": 3})))
    runner.start()
    deadline = time.monotonic() + 5
    while not board.pending() and time.monotonic() < deadline:
        time.sleep(0.01)
    task = board.pending()[0]
    assert task.prompt == "Serve table 3" and task.actor == "staff"
    assert board.complete(task.id, {"by": "Hanako"})
    runner.join(timeout=5)
    result = box["result"]
    assert result.status == "succeeded" and result.variables["served"]["by"] == "Hanako"
    assert not board.complete("task-unknown")
    short = parse(wf.source.replace("timeout: 5", "timeout: 0.1"))
    result = ex.run(short, {"table": 1})
    assert result.status == "failed" and result.steps[0].status in ("failed", "timeout")
    ex.close()


def test_a_broken_recorder_does_not_break_runs(robots, small):
    class Broken:
        def record(self, kind, payload):
            raise RuntimeError("database down")

    ex = Executor({"ros_service": robots, "wait": WaitAdapter()}, Broken())
    assert ex.run(parse(small)).status == "succeeded"
    ex.close()


def test_teahouse_workflows_run_with_simulated_robots_and_humans(executor, robots, teahouse_dir, tmp_path):
    """All eight teahouse workflows, those that fire the reception rules on the real engine too."""
    from gateway.config import Settings
    from gateway.engine import Engine
    from gateway.workflow.adapters import RulesAdapter
    from gateway.workflow.loader import load

    engine = Engine(Settings(data_dir=str(tmp_path / "data")))
    assert engine.seed(engine.settings.engine.rules_dir)["reception"] == "seeded v1"
    executor.adapters["fire_rules"] = RulesAdapter(engine)
    fired_rules = []
    for path in sorted(teahouse_dir.glob("*.yaml")):
        wf = load(path)
        if any(m.kind == "dialogue" for m in wf.modules.values()):
            continue  # take_order talks with the customer: tests/dialogue/test_take_order_workflow.py runs it
        result = executor.run(wf)
        assert result.status == "succeeded", (path.name, result.error)
        assert result.actions(), path.name
        if any(m.kind == "fire_rules" for m in wf.modules.values()):
            fired_rules.append(path.name)
    assert fired_rules == ["1_greeting.yaml"]
    assert any(c["module"] == "say" for c in robots.calls)  # the reception rules' then-part spoke
    approach = [c for c in robots.calls if c["step"] == "approach"][0]
    assert approach["params"]["x"] == 1.0 + 1.2  # the ontology's robot-human distance (1.2 in the fixture)
