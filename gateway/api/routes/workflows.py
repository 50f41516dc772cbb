"""REST for workflows: list, read, validate, replace (live), run; runs, manual tasks, generated code;
and the palette of the workbench's visual workflow editor (the editor itself is the Workflows
section of the workbench shell, ``/workbench/workflows/<name>``).

Why thin: everything is in ``gateway.workflow``; this maps HTTP to the :class:`WorkflowService`
kept in the gateway (versions in the Information State, followed by every gateway process).

    GET  /api/workflows                        [{name, title, version, ...}]
    GET  /api/workflows/{name}                 {name, version, text, workflow_view, scenario_view}
    GET  /api/workflows/{name}/versions        [{version, updated_at, author, comment, hash}]
    GET  /api/workflows/{name}/versions/{v}    {version info, text} (for diffs)
    GET  /api/workflows/palette                modules the editor offers, typed parameters
    POST /api/workflows/validate               {"text": yaml} or {"document": {...}, "previous_text"}
                                               -> {"valid", "problems", "text", "document", views}
    PUT  /api/workflows/{name}                 {"text", "comment", "base_version"} -> 201 {name, version}
    POST /api/workflows/{name}/rollback        {"version"} -> 201 {name, version} (the pointer moves back)
    DELETE /api/workflows/{name}               stop offering it (versions and history stay)
    GET  /api/workflows/{name}/history         deploys, rollbacks, deletes
    POST /api/workflows/{name}/run             {"inputs": {...}, "wait": true} -> the run (or 202 {run_id})
    POST /api/workflows/try                    {"text", "inputs"} -> 202 {run_id}: unsaved edits, simulated robots
    GET  /api/workflows/runs[?workflow=&limit=], GET /api/workflows/runs/{run_id} (202 + steps so far)
    GET  /api/workflows/manual, POST /api/workflows/manual/{task_id}/done {"result": {...}}
    GET  /api/workflows/{name}/code            the generated standalone rclpy node (text/x-python)
"""

from __future__ import annotations

from functools import lru_cache
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Query, Request
from fastapi import Path as PathParam
from fastapi.responses import PlainTextResponse, Response
from pydantic import BaseModel, ConfigDict, Field, model_validator

from gateway.api.auth import Principal, author, caller
from gateway.api.deps import gateway_of
from gateway.api.errors import ApiError
from gateway.api.jsonio import JSON, JsonRoute
from gateway.config import PROJECT_ROOT
from gateway.workflow.codegen import generate
from gateway.workflow.diagram import scenario_view, workflow_view
from gateway.workflow.loader import WorkflowInvalid, schema
from gateway.workflow.palette import Interface, build_palette, read_interfaces
from gateway.workflow.registry import WorkflowConflict, WorkflowNotFound
from gateway.workflow.render import read_document, to_yaml
from gateway.workflow.service import RealRobots, WorkflowService

router = APIRouter(tags=["workflows"], route_class=JsonRoute)

WorkflowName = Annotated[str, PathParam(pattern=r"^[A-Za-z_][A-Za-z0-9_]*$", max_length=100)]
MAX_VERSION = 2**31 - 1
VersionNumber = Annotated[int, PathParam(ge=1, le=MAX_VERSION)]
MAX_TEXT = 1_000_000
INTERFACES_DIR = PROJECT_ROOT / "ros"


class TextBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    text: str = Field(min_length=1, max_length=MAX_TEXT, description="The workflow as YAML.")


class ValidateBody(BaseModel):
    """Either the YAML text, or the document the visual editor changed (written back to YAML under
    the leading comments of ``previous_text``)."""

    model_config = ConfigDict(extra="forbid")
    text: str | None = Field(default=None, min_length=1, max_length=MAX_TEXT, description="The workflow as YAML.")
    document: dict[str, Any] | None = Field(default=None, description="The workflow as data (the parsed YAML).")
    previous_text: str = Field(default="", max_length=MAX_TEXT)

    @model_validator(mode="after")
    def _one_of(self) -> ValidateBody:
        if (self.text is None) == (self.document is None):
            raise ValueError("give either 'text' or 'document'")
        return self


class ReplaceBody(TextBody):
    comment: str = Field(default="", max_length=2000)
    base_version: int | None = Field(default=None, ge=0,
                                     description="The version this edit started from; 409 if no longer current.")


class RollbackBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    version: int = Field(ge=1, le=MAX_VERSION)
    comment: str = Field(default="", max_length=2000)


class RunBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    inputs: dict[str, Any] = Field(default_factory=dict)
    wait: bool = Field(default=True, description="false: start in the background and answer 202 {run_id}.")


class TryBody(TextBody):
    inputs: dict[str, Any] = Field(default_factory=dict)


class DoneBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    result: dict[str, Any] = Field(default_factory=dict)


def service(request: Request) -> WorkflowService:
    """The gateway's workflow service."""
    return gateway_of(request).workflows


def _entry(svc: WorkflowService, name: str) -> Any:
    try:
        return svc.registry.current(name)
    except WorkflowNotFound as exc:
        raise ApiError(404, str(exc), name=name) from None


def _invalid(exc: WorkflowInvalid) -> ApiError:
    return ApiError(422, "workflow invalid", problems=[p.to_dict() for p in exc.problems])


# Fixed paths first: "runs", "manual", "validate", "schema" are reserved workflow names.

@router.get("/api/workflows")
def list_workflows(request: Request, _: Principal = Depends(caller)) -> JSON:
    """Every workflow with its current version."""
    svc = service(request)
    out = []
    for name in svc.registry.names():
        entry = svc.registry.current(name)
        out.append({"name": name, "title": entry.workflow.title, "business_process": entry.workflow.business_process,
                    **entry.info.to_dict()})
    return JSON(out)


@router.get("/api/workflows/schema")
def get_schema(_: Principal = Depends(caller)) -> JSON:
    """The JSON schema workflow files are validated against."""
    return JSON(schema())


@router.post("/api/workflows/validate")
def validate(body: ValidateBody, request: Request, _: Principal = Depends(caller)) -> JSON:
    """Check a workflow without deploying it. Always answers the text and, when the YAML parses, the
    document (what the visual editor shows); on success also the two views."""
    text = body.text if body.text is not None else to_yaml(body.document or {}, body.previous_text)
    document = body.document if body.document is not None else read_document(text)
    wf, problems = service(request).validate(text)
    if wf is None:
        return JSON({"valid": False, "problems": [p.to_dict() for p in problems], "text": text, "document": document})
    return JSON({"valid": True, "problems": [], "name": wf.name, "text": text, "document": document,
                 "workflow_view": workflow_view(wf), "scenario_view": scenario_view(wf)})


@lru_cache(maxsize=1)
def _interfaces() -> dict[str, Interface]:
    return read_interfaces(INTERFACES_DIR)


@router.get("/api/workflows/palette")
def palette(request: Request, _: Principal = Depends(caller)) -> JSON:
    """What the visual editor offers: robot services (ROS interfaces x robots), fire business rules
    (deployed rule sets), ontology look-ups (its values), waits, staff tasks and branches, each with
    typed parameters (type, choices, required, default, description)."""
    gw = gateway_of(request)
    svc = service(request)
    workflows = []
    for name in svc.registry.names():
        try:
            workflows.append(svc.registry.get(name))
        except (WorkflowNotFound, WorkflowInvalid):  # deleted meanwhile, or unreadable: its robots drop out
            continue
    return JSON(build_palette(
        configured_robots=gw.settings.ros.robots, interfaces=_interfaces(), workflows=workflows,
        rulesets=sorted(info.name for info in gw.engine.list_rulesets()),
        ontology_values=gw.knowledge.values()))


@router.post("/api/workflows/try", status_code=202)
def try_edits(body: TryBody, request: Request, _: Principal = Depends(author)) -> JSON:
    """Run an unsaved text on the simulated robots (the editor's "try my edits"): 202 ``{run_id}``,
    followed with ``GET /api/workflows/runs/{run_id}``; 422 ``problems``; 409 where robots are real."""
    try:
        run_id = service(request).try_text(body.text, body.inputs)
    except WorkflowInvalid as exc:
        raise _invalid(exc) from None
    except RealRobots as exc:
        raise ApiError(409, str(exc)) from None
    return JSON({"run_id": run_id, "status": "running"}, status_code=202)


@router.get("/api/workflows/runs")
def list_runs(request: Request, workflow: str | None = None, limit: int = Query(50, ge=1, le=1000),
              _: Principal = Depends(caller)) -> JSON:
    """Finished runs, newest first."""
    return JSON([r.to_dict() for r in service(request).runs(workflow, limit)])


@router.get("/api/workflows/runs/{run_id}")
def get_run(run_id: str, request: Request, _: Principal = Depends(caller)) -> JSON:
    """One run: 200 with the result, 202 ``{"status": "running", "steps": [...]}`` (the steps done so
    far) while it runs, 404 if unknown."""
    svc = service(request)
    try:
        result = svc.get_run(run_id)
    except KeyError:
        raise ApiError(404, f"run {run_id!r} not found (or no longer kept)", run_id=run_id) from None
    if result is None:
        return JSON({"run_id": run_id, "status": "running", "steps": svc.steps_so_far(run_id)}, status_code=202)
    return JSON(result.to_dict())


@router.get("/api/workflows/manual")
def manual_tasks(request: Request, _: Principal = Depends(caller)) -> JSON:
    """Human steps waiting for someone to do them."""
    return JSON([t.to_dict() for t in service(request).manual.pending()])


@router.post("/api/workflows/manual/{task_id}/done")
def manual_done(task_id: str, body: DoneBody, request: Request, _: Principal = Depends(caller)) -> JSON:
    """Mark a human step done (its ``result`` becomes the step's output)."""
    if not service(request).manual.complete(task_id, body.result):
        raise ApiError(404, f"no manual task {task_id!r} is waiting", task_id=task_id)
    return JSON({"task_id": task_id, "done": True})


@router.get("/api/workflows/{name}")
def get_workflow(name: WorkflowName, request: Request, _: Principal = Depends(caller)) -> JSON:
    """The current version: YAML text, version info and both views."""
    entry = _entry(service(request), name)
    wf = entry.workflow
    return JSON({**entry.info.to_dict(), "title": wf.title, "text": wf.source,
                 "workflow_view": workflow_view(wf), "scenario_view": scenario_view(wf)})


@router.get("/api/workflows/{name}/versions")
def versions(name: WorkflowName, request: Request, _: Principal = Depends(caller)) -> JSON:
    try:
        return JSON([v.to_dict() for v in service(request).registry.versions(name)])
    except WorkflowNotFound as exc:
        raise ApiError(404, str(exc), name=name) from None


@router.get("/api/workflows/{name}/versions/{version}")
def version_text(name: WorkflowName, version: VersionNumber, request: Request,
                 _: Principal = Depends(caller)) -> JSON:
    """One stored version's text (the editor compares two of them)."""
    try:
        entry = service(request).registry.version(name, version)
    except WorkflowNotFound as exc:
        raise ApiError(404, str(exc), name=name, version=version) from None
    return JSON({**entry.info.to_dict(), "text": entry.workflow.source})


@router.put("/api/workflows/{name}", status_code=201)
def replace(name: WorkflowName, body: ReplaceBody, request: Request, who: Principal = Depends(author)) -> JSON:
    """Validate and make live: the next run uses it (runs in progress finish with their version).
    422 ``{"problems": [{file, path, line, column, message}]}``; 409 ``{"current": n}`` if stale."""
    try:
        info = service(request).registry.replace(name, body.text, author=who.name, comment=body.comment,
                                                 base_version=body.base_version)
    except WorkflowInvalid as exc:
        raise _invalid(exc) from None
    except WorkflowConflict as exc:
        raise ApiError(409, "base version changed", current=exc.current) from None
    return JSON({"name": info.name, "version": info.version}, status_code=201)


@router.post("/api/workflows/{name}/rollback", status_code=201)
def rollback(name: WorkflowName, body: RollbackBody, request: Request, who: Principal = Depends(author)) -> JSON:
    try:
        info = service(request).registry.rollback(name, body.version, author=who.name, comment=body.comment)
    except WorkflowNotFound as exc:
        raise ApiError(404, str(exc), name=name) from None
    return JSON({"name": info.name, "version": info.version}, status_code=201)


@router.delete("/api/workflows/{name}")
def delete(name: WorkflowName, request: Request, who: Principal = Depends(author)) -> JSON:
    try:
        service(request).registry.delete(name, author=who.name)
    except WorkflowNotFound as exc:
        raise ApiError(404, str(exc), name=name) from None
    return JSON({"name": name, "deleted": True})


@router.get("/api/workflows/{name}/history")
def history(name: WorkflowName, request: Request, _: Principal = Depends(caller)) -> JSON:
    events = service(request).registry.history(name)
    if not events:
        raise ApiError(404, f"workflow {name!r} not found", name=name)
    return JSON(events)


@router.post("/api/workflows/{name}/run")
def run(name: WorkflowName, body: RunBody, request: Request, _: Principal = Depends(caller)) -> JSON:
    """Run the current version. A failed step gives 200 with ``status: failed`` and the trace."""
    svc = service(request)
    _entry(svc, name)
    if not body.wait:
        return JSON({"run_id": svc.start(name, body.inputs), "status": "running"}, status_code=202)
    return JSON(svc.run(name, body.inputs).to_dict())


@router.get("/api/workflows/{name}/code")
def code(name: WorkflowName, request: Request, _: Principal = Depends(caller)) -> Response:
    """The workflow as a standalone Python rclpy node (what the papers' editor generated)."""
    entry = _entry(service(request), name)
    return PlainTextResponse(generate(entry.workflow, version=entry.info.version), media_type="text/x-python")
