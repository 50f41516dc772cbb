"""The workflow format: the teahouse files are valid; bad files give every error with its place."""

from __future__ import annotations

import pytest

from gateway.workflow.loader import WorkflowInvalid, load, parse
from gateway.workflow.model import BranchStep, ModuleStep


def problems(text: str) -> list[tuple[int, int, str, str]]:
    with pytest.raises(WorkflowInvalid) as info:
        parse(text, file="edit.yaml")
    assert all(p.file == "edit.yaml" for p in info.value.problems)
    return [(p.line, p.column, p.path, p.message) for p in info.value.problems]


def test_the_seven_teahouse_business_processes_load(teahouse_dir):
    workflows = [load(path) for path in sorted(teahouse_dir.glob("*.yaml"))]
    assert sorted(wf.business_process for wf in workflows) == [1, 2, 3, 4, 5, 6, 7, 8]  # + clearing a table
    actors = {wf.business_process: {a.name for a in wf.actors.values() if a.kind in ("robot", "human")}
              for wf in workflows}
    assert "pepper" in actors[1] and "pepper" in actors[2] and "pepper" in actors[3] and "pepper" in actors[7]
    assert {"jaco2", "hsr"} <= actors[4]
    for number in (5, 6):
        wf = next(w for w in workflows if w.business_process == number)
        assert any(m.kind == "manual" and wf.actors[m.actor].kind == "human" for m in wf.modules.values())


def test_model_of_a_small_workflow(small):
    wf = parse(small)
    assert wf.route.services == ("reception",) and wf.route.start == "arrival"
    steps = wf.processes["greet"].steps
    assert steps[0].id == "greet_1"  # ids default to process + position
    assert isinstance(steps[1], BranchStep) and steps[1].condition == "n == 2"
    assert isinstance(steps[1].then[0], ModuleStep) and steps[1].then[0].save == "said"
    assert wf.step_actor(steps[1].then[0]) == "pepper"


def test_yaml_syntax_error_has_line_and_column():
    found = problems("workflow: x\nmodules: [a\n")
    assert len(found) == 1
    line, column, _path, message = found[0]
    assert line == 3 and column >= 1 and "YAML syntax error" in message


def test_schema_errors_point_at_the_field(small):
    text = small.replace("params: {seconds: 0.01}}", "params: {seconds: 0.01}, colour: red}")
    text = text.replace("      - {id: pause, module: pause}", "      - {id: pause, module: pause, process: greet}")
    found = problems(text)
    lines = text.splitlines()
    colour_line = next(i for i, line in enumerate(lines, 1) if "colour" in line)
    assert (colour_line, lines[colour_line - 1].index("colour") + 1, "modules.pause.colour",
            "unknown field 'colour'") in found
    step_line = next(i for i, line in enumerate(lines, 1) if "process: greet}" in line)
    assert any(line == step_line and path == "processes.greet.steps[2]" and "exactly one of" in msg
               for line, _c, path, msg in found)


def test_missing_required_fields_and_bad_kind(small):
    text = small.replace("kind: ros_service, actor: pepper, service: /pepper/speak, ",
                         "kind: ros_service, actor: pepper, ")
    found = problems(text)
    assert any(path == "modules.say" and "'service' is required" in msg for _l, _c, path, msg in found)
    found = problems(small.replace("kind: wait", "kind: teleport"))
    assert any(path == "modules.pause.kind" and "'teleport' is not one of" in msg for _l, _c, path, msg in found)


def test_reference_errors_are_all_reported_with_places(small):
    text = (small.replace("actor: pepper, service", "actor: peper, service")
            .replace("{id: pause, module: pause}", "{id: pause, module: nap}")
            .replace('if: "n == 2"', 'if: "n == "')
            .replace("processes: [greet]", "processes: [greet, dance]")
            .replace("{id: echo, module: say", "{id: two, module: say"))
    found = problems(text)
    messages = {(path, msg.split(" (")[0]) for _l, _c, path, msg in found}
    assert ("modules.say.actor", "unknown actor 'peper'") in messages
    assert ("processes.greet.steps[2].module", "unknown module 'nap'") in messages
    assert ("services.reception.processes[1]", "unknown process 'dance'") in messages
    assert any(path == "processes.greet.steps[1].if" and "syntax error" in msg for path, msg in messages)
    assert any(path == "processes.greet.steps[3]" and "used twice" in msg for path, msg in messages)
    assert all(line > 0 and column > 0 for line, column, _p, _m in found)
    line_of_nap = next(line for line, _c, path, _m in found if path.endswith("steps[2].module"))
    assert text.splitlines()[line_of_nap - 1].strip().startswith("- {id: pause, module: nap}")


def test_process_cycles_are_rejected(small):
    text = small.replace("      - {id: pause, module: pause}", "      - {id: again, process: greet}")
    found = problems(text)
    assert any("cycle" in msg and "greet -> greet" in msg for *_x, msg in found)


def test_not_a_mapping():
    assert problems("- a\n- b\n")[0][3].startswith("a workflow must be a mapping")


def test_command_line_validate_and_generate(teahouse_dir, tmp_path):
    """``printeps workflow validate|generate`` (the workflows' part of the one CLI)."""
    from typer.testing import CliRunner

    from gateway.cli import app

    runner = CliRunner()
    ok = runner.invoke(app, ["workflow", "validate", *map(str, sorted(teahouse_dir.glob("*.yaml")))])
    assert ok.exit_code == 0, ok.output
    bad = tmp_path / "bad.yaml"
    bad.write_text("workflow: bad\nmodules: {}\nprocesses: {}\nservices: {}\nroute: {services: []}\n")
    refused = runner.invoke(app, ["workflow", "validate", str(bad)])
    assert refused.exit_code == 1
    assert f"{bad}:2:10: modules:" in refused.output
    out = tmp_path / "node.py"
    assert runner.invoke(app, ["workflow", "generate", str(teahouse_dir / "7_thanking.yaml"), "-o", str(out)]).exit_code == 0
    compile(out.read_text(), str(out), "exec")


def test_yaml_aliases_are_refused(small):
    text = small.replace("inputs: {customers: [a, b]}", "inputs: &x {customers: [a, b]}\nextra: *x")
    found = problems(text)
    assert found == [(3, 8, "", "YAML aliases (*name) are not allowed in workflows")]


def test_duplicate_keys_and_deep_nesting_are_refused(small):
    found = problems(small.replace("inputs: {customers: [a, b]}", "inputs: {customers: [a, b]}\ninputs: {}"))
    assert (3, 1, "inputs", "duplicate key 'inputs' (the earlier value would be lost)") in found
    assert problems("a: " + "[" * 500 + "]" * 500)[0][3] == "the document is nested too deeply"
