"""Replacing workflows while running, versions kept in the catalog (the Information State in a
gateway), and the workflows/ folder as the seed of an empty catalog."""

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


def test_replace_while_running_next_run_uses_the_new_version():
    registry = WorkflowRegistry()
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


def test_invalid_replacement_changes_nothing_and_conflicts_are_detected():
    registry = WorkflowRegistry()
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


def test_versions_survive_a_restart_and_rollback(store):
    from gateway.store.catalog import MongoCatalog

    registry = WorkflowRegistry(MongoCatalog(store.db, "first"))
    registry.replace("serve", HUMAN.replace("TEXT", "v1"), author="a")
    registry.replace("serve", HUMAN.replace("TEXT", "v2"), author="b", comment="louder")
    again = WorkflowRegistry(MongoCatalog(store.db, "restarted"))
    again.load()
    assert [(v.version, v.author) for v in again.versions("serve")] == [(1, "a"), (2, "b")]
    assert "v2" in again.get("serve").source
    assert again.rollback("serve", 1).version == 1  # the pointer moves back, as for rule sets
    assert "v1" in again.get("serve").source
    registry.sync("serve")  # what the change follower does in the other process
    assert "v1" in registry.get("serve").source
    assert [h["event"] for h in again.history("serve")] == ["deploy", "deploy", "rollback"]


def test_source_folder_only_seeds_what_the_catalog_never_had(tmp_path, teahouse_dir):
    source = tmp_path / "workflows"
    shutil.copytree(teahouse_dir, source)
    registry = WorkflowRegistry()
    report = registry.seed(source)
    assert len(report) == 8 and set(report.values()) == {"seeded v1"}
    assert len(registry.names()) == 8  # the seven business processes + clearing a table
    registry.replace("thanking", registry.get("thanking").source.replace("Please come again.", "See you!"))
    path = source / "7_thanking.yaml"
    path.write_text(path.read_text().replace("Thank you very much.", "Thank you!"))
    (source / "broken.yaml").write_text("workflow: broken\nmodules: {}\n")
    report = registry.seed(source)
    assert report["broken.yaml"].startswith("failed: ") and "broken.yaml" in report["broken.yaml"]
    assert report["thanking"] == "kept v2" and report["greeting"] == "kept v1"
    assert "See you!" in registry.get("thanking").source  # the live edit is kept over the changed file
    assert "Thank you!" not in registry.get("thanking").source
    assert registry.current("thanking").info.author == "anonymous"
