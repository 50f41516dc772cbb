"""Replacing workflows while running, versions kept on disk, and the workflows/ folder as the start."""

from __future__ import annotations

import shutil
import threading
import time

import pytest

from gateway.workflow.adapters import ManualBoard, SimulatedRobots
from gateway.workflow.executor import Executor
from gateway.workflow.loader import WorkflowInvalid
from gateway.workflow.registry import WorkflowConflict, WorkflowNotFound, WorkflowRegistry

HUMAN = """\
workflow: serve
actors: {staff: {kind: human}, pepper: {kind: robot}}
modules:
  serve: {kind: manual, actor: staff, timeout: 5}
  say: {kind: ros_service, actor: pepper, service: /pepper/speak, type: printeps_interfaces/srv/Speak}
processes:
  p:
    steps:
      - {id: serve, module: serve}
      - {id: talk, module: say, with: {text: "TEXT"}}
services: {s: {processes: [p]}}
route: {services: [s]}
"""


def test_replace_while_running_next_run_uses_the_new_version(tmp_path):
    registry = WorkflowRegistry(None, tmp_path)
    registry.replace("serve", HUMAN.replace("TEXT", "old"), author="owner")
    board, robots = ManualBoard(simulate=False), SimulatedRobots()
    ex = Executor({"manual": board, "ros_service": robots})
    box: dict = {}
    running = threading.Thread(target=lambda: box.setdefault("first", ex.run(registry.get("serve"))))
    running.start()
    deadline = time.monotonic() + 5
    while not board.pending() and time.monotonic() < deadline:
        time.sleep(0.01)
    info = registry.replace("serve", HUMAN.replace("TEXT", "new"), author="owner", comment="suggestion 6")
    assert info.version == 2
    board.complete(board.pending()[0].id)
    running.join(timeout=5)
    assert box["first"].status == "succeeded"
    assert robots.calls[-1]["params"]["text"] == "old"  # the run in progress kept its version
    board.simulate = True
    assert ex.run(registry.get("serve")).status == "succeeded"
    assert robots.calls[-1]["params"]["text"] == "new"
    ex.close()


def test_invalid_replacement_changes_nothing_and_conflicts_are_detected(tmp_path):
    registry = WorkflowRegistry(None, tmp_path)
    registry.replace("serve", HUMAN.replace("TEXT", "v1"))
    with pytest.raises(WorkflowInvalid) as info:
        registry.replace("serve", HUMAN.replace("module: say", "module: shout"))
    assert info.value.problems[0].path == "processes.p.steps[1].module"
    with pytest.raises(WorkflowInvalid):
        registry.replace("other", HUMAN)  # the text names workflow 'serve'
    assert registry.current("serve").info.version == 1
    with pytest.raises(WorkflowConflict) as conflict:
        registry.replace("serve", HUMAN.replace("TEXT", "v2"), base_version=0)
    assert conflict.value.current == 1
    assert registry.replace("serve", HUMAN.replace("TEXT", "v2"), base_version=1).version == 2
    with pytest.raises(WorkflowNotFound):
        registry.get("nope")


def test_versions_survive_a_restart_and_rollback(tmp_path):
    registry = WorkflowRegistry(None, tmp_path)
    registry.replace("serve", HUMAN.replace("TEXT", "v1"), author="a")
    registry.replace("serve", HUMAN.replace("TEXT", "v2"), author="b", comment="louder")
    again = WorkflowRegistry(None, tmp_path)
    again.load()
    assert [(v.version, v.author) for v in again.versions("serve")] == [(1, "a"), (2, "b")]
    assert "v2" in again.get("serve").source
    assert again.rollback("serve", 1).version == 3
    assert "v1" in again.get("serve").source


def test_source_folder_is_imported_once_and_again_when_a_file_changes(tmp_path, teahouse_dir):
    source = tmp_path / "workflows"
    shutil.copytree(teahouse_dir, source)
    registry = WorkflowRegistry(source, tmp_path / "data")
    assert registry.load() == []
    assert len(registry.names()) == 7
    registry.replace("thanking", registry.get("thanking").source.replace("Please come again.", "See you!"))
    restarted = WorkflowRegistry(source, tmp_path / "data")
    restarted.load()
    assert "See you!" in restarted.get("thanking").source  # the live edit is kept over the unchanged file
    path = source / "7_thanking.yaml"
    path.write_text(path.read_text().replace("Thank you very much.", "Thank you!"))
    (source / "broken.yaml").write_text("workflow: broken\nmodules: {}\n")
    restarted = WorkflowRegistry(source, tmp_path / "data")
    problems = restarted.load()
    assert problems and all(p.file.endswith("broken.yaml") for p in problems)
    assert "Thank you!" in restarted.get("thanking").source
    assert restarted.current("thanking").info.author == "filesystem"
