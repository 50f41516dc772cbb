"""Fixtures of the workflow tests: the teahouse workflows, simulated robots/humans, a small workflow."""

from __future__ import annotations

from pathlib import Path

import pytest

from gateway.config import PROJECT_ROOT
from gateway.workflow.adapters import ManualBoard, OntologyValueAdapter, SimulatedRobots, WaitAdapter
from gateway.workflow.executor import Executor
from gateway.workflow.recorder import MemoryRecorder

TEAHOUSE = PROJECT_ROOT / "workflows"

SMALL = """\
workflow: small
inputs: {customers: [a, b]}
actors:
  pepper: {kind: robot, label: Pepper}
modules:
  say: {kind: ros_service, actor: pepper, service: /pepper/speak, type: printeps_interfaces/srv/Speak, params: {robot: pepper}}
  pause: {kind: wait, params: {seconds: 0.01}}
processes:
  greet:
    steps:
      - set: {n: "${len(input.customers)}"}
      - id: choose
        if: "n == 2"
        then:
          - {id: two, module: say, with: {text: "Welcome. Two seats?"}, save: said}
        else:
          - {id: other, module: say, with: {text: "Welcome. ${n} seats?"}}
      - {id: pause, module: pause}
      - {id: echo, module: say, with: {text: "${said.message}"}}
services:
  reception: {processes: [greet]}
route: {start: arrival, services: [reception], end: greeted}
"""


@pytest.fixture()
def small() -> str:
    return SMALL


@pytest.fixture()
def robots() -> SimulatedRobots:
    return SimulatedRobots()


@pytest.fixture()
def recorder() -> MemoryRecorder:
    return MemoryRecorder()


@pytest.fixture()
def executor(robots: SimulatedRobots, recorder: MemoryRecorder) -> Executor:
    values = {"pepper1.robotToHumanDistance": 1.2, "pepper1.robotToTableDistance": 0.5,
              "serving1.emptyCupReactionTime": 30, "cup1.pourQuantity": 160.0}  # the last one inferred by SWRL
    ex = Executor({"ros_service": robots, "ros_topic": robots, "wait": WaitAdapter(),
                   "manual": ManualBoard(simulate=True), "ontology_value": OntologyValueAdapter(values.get)},
                  recorder, default_timeout=5.0)
    yield ex
    ex.close()


@pytest.fixture()
def teahouse_dir() -> Path:
    return TEAHOUSE
