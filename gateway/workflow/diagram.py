"""What the workbench draws: the workflow view (route -> services -> processes -> steps) and the
scenario view (the same steps in order, one lane per actor).

Why on the server: the browser then needs no YAML parser and no knowledge of the model; the page
only lays out boxes. The same function serves saved workflows and unsaved edits being validated.
"""

from __future__ import annotations

from typing import Any

from gateway.workflow.model import BranchStep, ModuleStep, ProcessStep, SetStep, Step, Workflow


def workflow_view(wf: Workflow) -> dict[str, Any]:
    """The route as nested boxes: services, their processes, each process's steps (with branches)."""
    return {
        "name": wf.name,
        "title": wf.title or wf.name,
        "business_process": wf.business_process,
        "start": wf.route.start,
        "end": wf.route.end,
        "services": [
            {"name": s, "processes": list(wf.services[s].processes)} for s in wf.route.services
        ],
        "processes": {
            name: {"description": p.description, "steps": [_node(wf, step) for step in p.steps]}
            for name, p in wf.processes.items()
        },
        "actors": [{"name": a.name, "kind": a.kind, "label": a.label or a.name} for a in wf.actors.values()],
    }


def scenario_view(wf: Workflow) -> dict[str, Any]:
    """Steps in route order with their actor; branches are shown with their condition and arm."""
    rows: list[dict[str, Any]] = []
    for service in wf.route.services:
        for process in wf.services[service].processes:
            _flatten(wf, process, wf.processes[process].steps, rows, service, depth=0, branch="", seen=())
    lanes = [a.name for a in wf.actors.values()]
    for row in rows:
        if row["actor"] not in lanes:
            lanes.append(row["actor"])
    return {"name": wf.name, "lanes": lanes,
            "labels": {a.name: a.label or a.name for a in wf.actors.values()},
            "kinds": {a.name: a.kind for a in wf.actors.values()}, "steps": rows}


def _label(wf: Workflow, step: Step) -> str:
    if step.label:
        return step.label
    if isinstance(step, ModuleStep):
        params = step.params
        for key in ("text", "name", "location", "prompt", "seconds", "ruleset"):
            if key in params:
                return f"{step.module}: {params[key]}"
        return step.module
    if isinstance(step, ProcessStep):
        return f"process {step.process}"
    if isinstance(step, BranchStep):
        return f"if {step.condition}"
    return "set " + ", ".join(step.values)


def _node(wf: Workflow, step: Step) -> dict[str, Any]:
    node: dict[str, Any] = {"id": step.id, "label": _label(wf, step)}
    if isinstance(step, ModuleStep):
        module = wf.modules[step.module]
        node.update(type="module", module=step.module, kind=module.kind, actor=wf.step_actor(step))
    elif isinstance(step, ProcessStep):
        node.update(type="process", process=step.process)
    elif isinstance(step, BranchStep):
        node.update(type="branch", condition=step.condition,
                    then=[_node(wf, s) for s in step.then], otherwise=[_node(wf, s) for s in step.otherwise])
    else:
        node.update(type="set")
    return node


def _flatten(wf: Workflow, process: str, steps: tuple[Step, ...], rows: list[dict[str, Any]], service: str,
             depth: int, branch: str, seen: tuple[str, ...]) -> None:
    for step in steps:
        if isinstance(step, SetStep):
            continue
        row = {"id": step.id, "label": _label(wf, step), "process": process, "service": service,
               "depth": depth, "branch": branch, "actor": "system"}
        if isinstance(step, ModuleStep):
            row.update(actor=wf.step_actor(step) or "system", kind=wf.modules[step.module].kind)
            rows.append(row)
        elif isinstance(step, BranchStep):
            row.update(kind="branch")
            rows.append(row)
            _flatten(wf, process, step.then, rows, service, depth + 1, f"{step.id}: then", seen)
            _flatten(wf, process, step.otherwise, rows, service, depth + 1, f"{step.id}: else", seen)
        elif isinstance(step, ProcessStep) and step.process not in seen:
            _flatten(wf, step.process, wf.processes[step.process].steps, rows, service, depth + 1, branch,
                     seen + (process,))
