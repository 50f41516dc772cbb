"""A rule set's outline: its rules by name with their sentences, and where the rule set is used.

Why: an owner looking for "what Pepper says to a pair" needs the rules as a list of what they do,
and needs to know which of two similar rule sets the entrance sensors actually feed. Routes:

* ``GET /api/rulesets/{name}/outline`` — the live version's rules and what feeds the rule set.
* ``POST /api/rulesets/{name}/outline`` with ``{"files": draft}`` — the same for the text being
  edited (the workbench's rule list follows the editor).

``used_by`` lists each stream query whose rule binding names the rule set, each workflow step
whose ``fire_rules`` module fires it, and the ROS service ``fire_business_rules`` when the rule set
is the one it fires for requests naming none.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter
from pydantic import BaseModel, ConfigDict, Field

from gateway.api.deps import Caller, EngineDep, SettingsDep, StreamsDep, WorkflowsDep
from gateway.api.jsonio import JSON, JsonRoute
from gateway.api.routes.authoring import MAX_FILES, RuleSetName
from gateway.engine.outline import outline
from gateway.workflow.model import BranchStep, ModuleStep

router = APIRouter(tags=["rule authoring"], route_class=JsonRoute)


class OutlineBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    files: dict[str, str] = Field(max_length=MAX_FILES)


@router.get("/api/rulesets/{name}/outline")
def live_outline(name: RuleSetName, engine: EngineDep, settings: SettingsDep, streams: StreamsDep,
                 workflows: WorkflowsDep, _: Caller) -> JSON:
    """``{"rules": [{"name", "file", "line"|"row", "when", "then"}], "used_by": [{"kind", "name", "text"}]}``
    of the live version."""
    files = dict(engine.current(name).files)
    return JSON({"rules": outline(files), "used_by": used_by(name, settings, streams, workflows)})


@router.post("/api/rulesets/{name}/outline")
def draft_outline(name: RuleSetName, body: OutlineBody, settings: SettingsDep, streams: StreamsDep,
                  workflows: WorkflowsDep, _: Caller) -> JSON:
    """The outline of draft ``files`` (nothing compiled, nothing stored)."""
    return JSON({"rules": outline(dict(body.files)), "used_by": used_by(name, settings, streams, workflows)})


def used_by(name: str, settings: Any, streams: Any, workflows: Any) -> list[dict[str, str]]:
    """What feeds rule set ``name``, in words an owner reads."""
    out: list[dict[str, str]] = []
    for query in streams.queries():
        binding = query.get("binding") or {}
        if binding.get("ruleset") == name:
            fact = binding.get("fact_type")
            out.append({"kind": "query", "name": query["name"],
                        "text": f"the sensors' stream query {query['name']}"
                                + (f" (each result becomes a {fact})" if fact else "")})
    for wf_name in workflows.registry.names():
        try:
            workflow = workflows.registry.current(wf_name).workflow
        except Exception:  # noqa: BLE001 - a workflow that cannot be read feeds nothing we can name
            continue
        fires = {m.name for m in workflow.modules.values()
                 if m.kind == "fire_rules" and m.options.get("ruleset") == name}
        for process_name, process in workflow.processes.items():
            for step in _module_steps(process.steps):
                if step.module in fires or step.params.get("ruleset") == name:
                    out.append({"kind": "workflow", "name": f"{wf_name}/{process_name}/{step.id}",
                                "text": f"workflow {workflow.title or wf_name}, step “{step.label or step.id}” "
                                        f"(process {process_name})"})
    ros = getattr(settings, "ros", None)
    if ros is not None and getattr(ros, "ruleset", None) == name:
        out.append({"kind": "ros", "name": "fire_business_rules",
                    "text": "the robots' ROS service fire_business_rules (when a request names no rule set)"})
    return out


def _module_steps(steps: Any) -> list[ModuleStep]:
    found: list[ModuleStep] = []
    for step in steps:
        if isinstance(step, ModuleStep):
            found.append(step)
        elif isinstance(step, BranchStep):
            found.extend(_module_steps(step.then))
            found.extend(_module_steps(step.otherwise))
    return found

