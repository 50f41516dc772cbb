"""``/api/rulesets``: manage rule set versions and fire them.

Why the two styles here: management routes (rare, human-paced) use pydantic models so the OpenAPI
docs show their bodies; the fire route is the hot path and parses/serializes with orjson itself.
Engine calls block (they go into the JVM), so management routes are sync (FastAPI runs them in its
threadpool). The fire route is a :class:`gateway.api.lean_route.LeanRoute` (documented by FastAPI,
served without its dependency solving) and fires on the rule set's own threads
(:mod:`gateway.engine.bulkhead`): the event loop only parses, routes and answers.
"""

from __future__ import annotations

import difflib
import json
import re
import time
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Path as PathParam, Query, Request
from pydantic import BaseModel, ConfigDict, Field

from gateway.api.auth import check_bearer
from gateway.api.deps import Author, Caller, EngineDep, JobsDep, SettingsDep, correlation_id, wants_async
from gateway.api.errors import ApiError
from gateway.api.jsonio import JSON, JsonRoute, read_json
from gateway.api.lean_route import LeanRoute
from gateway.engine.errors import FactError
from gateway.engine.results import finished

NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"  # as gateway.engine.ruleset.check_name

RuleSetName = Annotated[str, PathParam(pattern=NAME_PATTERN, description="Rule set name (its folder name)")]
MAX_FILES = 500

router = APIRouter(tags=["rule sets"], route_class=JsonRoute)


class FilesBody(BaseModel):
    """Rule files of a rule set: file name -> text (``.drl``, ``.dsl``, ``.dslr``, decision tables
    ``.csv`` and ``.xlsx`` — the latter as a ``data:`` URL —, ``examples.json`` and test scenarios
    ``tests/<name>.yaml``); the engine checks names, sizes and content and answers 422 naming the file."""

    model_config = ConfigDict(extra="forbid")
    files: dict[str, str] = Field(min_length=1, max_length=MAX_FILES)


class DeployBody(FilesBody):
    comment: str = Field(default="", max_length=2000)
    base_version: int | None = Field(
        default=None, ge=0, description="The version this edit started from; 409 if it is no longer current."
    )
    force: bool = Field(default=False, description="Deploy even if test scenarios (tests/*.yaml) are red.")


class RollbackBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    version: int = Field(ge=1)
    comment: str = Field(default="", max_length=2000)


class TryBody(FilesBody):
    facts: list[dict[str, Any]] = Field(default_factory=list)


FIRE_SCHEMA: dict[str, Any] = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {
                "schema": {
                    "type": "object",
                    "required": ["facts"],
                    "properties": {
                        "facts": {
                            "type": "array",
                            "items": {
                                "type": "object",
                                "required": ["type"],
                                "properties": {"type": {"type": "string", "minLength": 1}},
                                "additionalProperties": True,
                            },
                        }
                    },
                }
            }
        },
    }
}


@router.get("/api/rulesets")
def list_rulesets(engine: EngineDep, _: Caller) -> JSON:
    """The current version of each rule set: name, version, deployed_at, author, comment, and
    ``policy``: "author" when an author may deploy it as it stands, "developer" when the rule
    policy refuses it (a developer deployed it; it keeps serving, an author's next deploy of such
    text is refused)."""
    return JSON([{**info.to_dict(), "policy": engine.policy_of(info)} for info in engine.list_rulesets()])


@router.get("/api/rulesets/{name}")
def get_ruleset(name: RuleSetName, engine: EngineDep, _: Caller) -> JSON:
    """The current version with its files."""
    return JSON(_version_dict(engine.current(name)))


@router.get("/api/rulesets/{name}/versions")
def list_versions(name: RuleSetName, engine: EngineDep, _: Caller) -> JSON:
    """Every kept version of the rule set, oldest first."""
    return JSON([info.to_dict() for info in engine.versions(name)])


@router.get("/api/rulesets/{name}/versions/{version}")
def get_version(name: RuleSetName, version: Annotated[int, PathParam(ge=1)], engine: EngineDep, _: Caller) -> JSON:
    """One version with its files."""
    return JSON(_version_dict(engine.version(name, version)))


@router.get("/api/rulesets/{name}/history")
def history(name: RuleSetName, engine: EngineDep, _: Caller) -> JSON:
    """Every deploy, rollback and delete of the rule set, and every change the rule policy refused
    (``event: "refused"``), oldest first, from any gateway process: who (``author``), in which
    ``role`` and from which process (``origin``)."""
    events = engine.history(name)
    if not events:
        engine.versions(name)  # 404 for a rule set that never existed
    return JSON(events)


def accepted(job: dict[str, Any]) -> JSON:
    """202 with the job and where to follow it."""
    return JSON(job, status_code=202, headers={"Location": f"/api/jobs/{job['id']}"})


@router.put("/api/rulesets/{name}", status_code=201)
def deploy(name: RuleSetName, body: DeployBody, request: Request, engine: EngineDep, jobs: JobsDep,
           who: Author) -> JSON:
    """Compile and make live on every gateway process; 422 with ``errors`` (file, line, column,
    message) if it does not compile, 422 ``{"kind": "scenarios", ...}`` if one of its test
    scenarios is red (unless ``force``), 422 ``{"kind": "policy", "errors": [...]}`` if the principal
    is an author and the rule policy refuses the files (nothing compiled), 409
    ``{"error": "base version changed", "current": n}``
    if ``base_version`` is stale. With ``Prefer: respond-async`` (or ``?async=true``): 202 and a
    build job (``Location: /api/jobs/{id}``) whose result or error is the same."""
    if wants_async(request):
        return accepted(jobs.submit("deploy", name, dict(body.files), author=who.name, comment=body.comment,
                                    base_version=body.base_version, force=body.force, role=who.role))
    info = engine.deploy(name, dict(body.files), author=who.name, comment=body.comment, base_version=body.base_version,
                         force=body.force, role=who.role)
    return JSON({"name": info.name, "version": info.version}, status_code=201)


@router.post("/api/rulesets/{name}/validate")
def validate(name: RuleSetName, body: DeployBody, request: Request, engine: EngineDep, jobs: JobsDep,
             who: Caller) -> JSON:
    """Compile only (the body a deploy takes is accepted as is): ``{"ok": bool, "errors": [...]}``;
    asynchronous as a job like the deploy. For any role but developer the errors are first those
    of the rule policy (then nothing is compiled)."""
    if wants_async(request):
        return accepted(jobs.submit("validate", name, dict(body.files), author=who.name, role=who.role))
    errors = engine.validate(name, dict(body.files), role=who.role)
    return JSON({"ok": not errors, "errors": [e.to_dict() for e in errors]})


@router.post("/api/rulesets/{name}/expand")
def expand(name: RuleSetName, body: FilesBody, engine: EngineDep, _: Caller) -> JSON:
    """The DRL each ``.dslr`` file expands to: ``{"expanded": {"x.dslr": "<drl>"}}``."""
    return JSON({"expanded": engine.expand(name, dict(body.files))})


@router.post("/api/rulesets/{name}/rollback")
def rollback(name: RuleSetName, body: RollbackBody, engine: EngineDep, who: Author) -> JSON:
    """Make an earlier version current again (on every gateway process)."""
    info = engine.rollback(name, body.version, author=who.name, comment=body.comment, role=who.role)
    return JSON({"name": info.name, "version": info.version})


@router.delete("/api/rulesets/{name}")
def delete(name: RuleSetName, engine: EngineDep, who: Author) -> JSON:
    """Undeploy the rule set (its fire endpoint answers 404 afterwards); its history stays."""
    engine.delete(name, author=who.name, role=who.role)
    return JSON({"name": name, "deleted": True})


async def fire(name: RuleSetName, request: Request, _: Caller) -> JSON:
    """Fire the current version on ``facts``: ``{"decision_id", "version", "actions", "fired", "facts",
    ...}``; 422 naming the bad fact/field. The decision is recorded with the ``X-Request-ID`` (or
    ``traceparent``) header as its correlation id. The fire runs on the rule set's own threads: 429
    (its queue is full, ``api.max_queue``) or 503 (it would wait longer than ``api.max_wait_s``), both
    ``{"kind": "overloaded", "ruleset", "limit", "setting"}`` with ``Retry-After``; 503 ``{"kind":
    "timeout"}`` when it runs past ``engine.fire_timeout_s`` (nothing recorded)."""
    return JSON(await fire_answer(request.app.state, name, await read_json(request), correlation_id(request)))


_NAME = re.compile(NAME_PATTERN)


async def _fire_arguments(request: Request) -> dict[str, Any]:
    """The fire endpoint's arguments, as FastAPI would solve them: the checked name, the caller."""
    principal = await check_bearer(request, "caller")
    name = request.path_params["name"]
    if _NAME.match(name) is None:
        raise ApiError(422, "invalid request", errors=[{"field": "path.name",
                                                        "message": f"String should match pattern '{NAME_PATTERN}'"}])
    return {"name": name, "request": request, "_": principal}


FIRE_ROUTE = LeanRoute("/api/rulesets/{name}/fire", fire, prepare=_fire_arguments, methods=["POST"],
                       tags=["rule sets"], openapi_extra=FIRE_SCHEMA)


async def fire_answer(state: Any, name: str, body: Any, correlation: str | None) -> dict[str, Any]:
    """The answer to a fire request with JSON ``body`` on rule set ``name`` (``state``: the app's
    state), fired on the rule set's bulkhead. Raises ApiError / EngineError for the app's error handlers."""
    facts = facts_from_body(body, state.settings.engine.max_facts)
    metrics = state.metrics
    engine = state.engine
    engine.live_compiled(name)  # 404 before a bulkhead is made for a name nobody deployed
    start = time.perf_counter()
    try:
        # the facts are encoded and the answer read here; only the Java fire runs on the rule set's
        # JVM threads, which never take the GIL (gateway.engine.bulkhead). Recorded here too.
        prepared = engine.prepare_fire(name, facts)
        answer, fire_ms = await state.bulkheads.of(name).fire(prepared, engine.fire_timeout_ms)
        result = finished(prepared, answer, fire_ms)
    except Exception as exc:
        metrics.fire_error(name, exc)
        raise
    engine.recorder.record(result, facts, origin="rest", correlation_id=correlation)
    out = result.to_dict()
    metrics.observe_fire(name, time.perf_counter() - start, len(out.get("fired") or ()))
    return out


def facts_from_body(body: Any, max_facts: int) -> list[dict[str, Any]]:
    """The fact list of a fire request, or ApiError 422 naming what is wrong and where."""
    if not isinstance(body, dict) or "facts" not in body:
        raise ApiError(422, "the body must be an object with a 'facts' list",
                       errors=[{"field": "facts", "message": "missing"}])
    extra = sorted(set(body) - {"facts"})
    if extra:
        raise ApiError(422, "unknown fields in the body", errors=[{"field": f, "message": "not allowed"} for f in extra])
    facts = body["facts"]
    if not isinstance(facts, list):
        raise ApiError(422, "'facts' must be a list", errors=[{"field": "facts", "message": "not a list"}])
    if len(facts) > max_facts:
        raise ApiError(422, f"too many facts: {len(facts)} > {max_facts}",
                       errors=[{"field": "facts", "message": f"at most {max_facts} facts"}])
    check_facts(facts)
    return facts


def check_facts(facts: list[Any]) -> None:
    """FactError (422 ``kind: "facts"``, as the engine's own refusals) unless every fact is an
    object with a type: one shape on the fire route and on the session routes (issue 32)."""
    errors = []
    for index, fact in enumerate(facts):
        if not isinstance(fact, dict):
            errors.append({"index": index, "type": None, "id": None, "field": None, "message": "a fact must be an object"})
        elif not isinstance(fact.get("type"), str) or not fact["type"]:
            errors.append({"index": index, "type": None, "id": _id_of(fact), "field": "type",
                           "message": "a fact needs a non-empty string 'type'"})
    if errors:
        raise FactError(errors)


def _id_of(fact: dict[str, Any]) -> str | None:
    value = fact.get("id")
    return value if isinstance(value, str) else None


@router.get("/api/rulesets/{name}/types")
def declared_types(name: RuleSetName, engine: EngineDep, _: Caller) -> JSON:
    """The fact types the rule set declares: ``{"Customer": {"id": "String", "age": "int"}}``."""
    return JSON(engine.declared_types(name))


@router.get("/api/rulesets/{name}/examples")
def examples(name: RuleSetName, engine: EngineDep, settings: SettingsDep, _: Caller) -> JSON:
    """The rule set's ``examples.json`` (``[{"name", "facts"}]``) or ``[]`` when it has none."""
    current = engine.current(name)  # 404 for unknown rule sets
    text = current.files.get("examples.json")
    source = "examples.json"
    if text is None:
        path = Path(settings.engine.rules_dir) / name / "examples.json"
        if not path.is_file():
            return JSON([])
        text, source = path.read_text(encoding="utf-8"), str(path)
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ApiError(422, f"{source}:{exc.lineno}:{exc.colno}: {exc.msg}") from None
    if not isinstance(data, list) or not all(isinstance(e, dict) and "facts" in e for e in data):
        raise ApiError(422, f"{source}: expected a list of {{'name', 'facts'}} objects")
    return JSON(data)


@router.post("/api/rulesets/{name}/try")
def try_files(name: RuleSetName, body: TryBody, engine: EngineDep, settings: SettingsDep, who: Caller) -> JSON:
    """Fire undeployed text (the workbench's "try it", not a decision); 422 ``{"errors": [...]}`` if
    it does not compile, 422 ``{"kind": "policy", ...}`` if the rule policy refuses it for the
    caller's role (checked before anything compiles or runs)."""
    facts = facts_from_body({"facts": body.facts}, settings.engine.max_facts)
    return JSON(engine.fire_files(dict(body.files), facts, role=who.role).to_dict())


@router.get("/api/rulesets/{name}/diff")
def diff(
    name: RuleSetName,
    engine: EngineDep,
    _: Caller,
    from_: Annotated[int | None, Query(alias="from", ge=1)] = None,
    to: Annotated[int | None, Query(ge=1)] = None,
) -> JSON:
    """Unified diff per changed file between two versions (default: previous -> current)."""
    if to is None:
        to = engine.current(name).info.version
    if from_ is None:
        from_ = max(1, to - 1)
    old, new = engine.version(name, from_), engine.version(name, to)
    return JSON({"name": name, "from": from_, "to": to, "files": file_diffs(old.files, new.files, from_, to)})


def file_diffs(old: dict[str, str], new: dict[str, str], a: int, b: int) -> dict[str, str]:
    """file name -> unified diff text, for files that differ (added/removed files diff against empty)."""
    out = {}
    for fname in sorted(set(old) | set(new)):
        before, after = old.get(fname, ""), new.get(fname, "")
        if before == after:
            continue
        lines = difflib.unified_diff(
            before.splitlines(keepends=True), after.splitlines(keepends=True),
            fromfile=f"v{a}/{fname}", tofile=f"v{b}/{fname}",
        )
        out[fname] = "".join(lines)
    return out


def _version_dict(rv: Any) -> dict[str, Any]:
    return {**rv.info.to_dict(), "files": dict(rv.files)}


@router.get("/api/whoami")
async def whoami(who: Caller) -> JSON:
    """The identity and role of the presented token (``anonymous``/``developer`` in open mode)."""
    return JSON(who.to_dict())
