"""KIE Server 7.x compatible endpoints: a KIE client switches to this gateway by changing its URL.

``/kie-server/services/rest/server``: server info, ``readycheck``, ``healthcheck``; containers
(a rule set is a container: id = rule set name) — list, get, ``PUT`` with a release id, ``DELETE``,
``GET``/``POST …/release-id`` to move to another version (a number or ``LATEST``); and
``POST …/containers/instances/{id}`` with a batch of commands (:mod:`gateway.api.kie.batch`).

A batch runs on the session its ``lookup`` names (:mod:`gateway.engine.sessions`): a declared
stateful ksession (``defaultKieSession`` unless the rule set's ``kmodule.xml`` says otherwise)
is one live session whose facts persist across calls; a stateless one, or no lookup (see
``sessions.no_lookup``), runs in a fresh session. Every batch that fires is a decision.

Every answer is KIE's ``ServiceResponse`` JSON ``{"type": "SUCCESS"|"FAILURE", "msg", "result"}``,
errors included. Statuses: where KIE Server answers a FAILURE with 200 (get container, release id)
so does the gateway, since KIE clients branch on ``type`` there; where KIE answers an error status
(a failed batch: 500; a failed ``PUT``: 400) the gateway answers the 4xx that names the kind of
problem — 400 unreadable body, 404 unknown container or session, 415 XML, 422 a command refused or
the rules failed, 429 a limit or the container's full queue, 503 a batch that would wait too long
or a fire halted by its time limit — and 410/503 for a session whose owner process is gone/unreachable.
"""

from __future__ import annotations

import logging
import time
from typing import Any, Callable

from fastapi import APIRouter, Depends, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import Response
from fastapi.routing import APIRoute
from starlette.exceptions import HTTPException

from gateway.api.auth import Principal, check_kie, kie_caller, require_kie
from gateway.api.deps import correlation_id
from gateway.api.errors import ApiError, command_failed_status, retry_after
from gateway.api.forwarding import Misdirected, OwnerUnreachable, forward
from gateway.engine.durable import JournalRefused, NotYetShared, RebuildFailed, Rebuilding
from gateway.api.jsonio import JSON, BadBody, parse_json, run_blocking
from gateway.api.lean_route import LeanRoute
from gateway.api.kie.batch import (
    Batch,
    BatchError,
    Marshal,
    execution_results,
    parse_batch,
)
from gateway.api.kie.containers import (
    LATEST,
    ReleaseIdError,
    container_resource,
    conversation_id,
    external_release_id,
    parse_release_id,
    release_id,
    server_info,
    service_response,
)
from gateway.engine import EngineError, RuleSetNotFound, VersionNotFound
from gateway.engine.errors import Overloaded
from gateway.engine.session import CommandFailed
from gateway.engine.sessions import (
    SessionElsewhere,
    SessionGone,
    SessionLimit,
    SessionNotFound,
)

log = logging.getLogger(__name__)

PREFIX = "/kie-server/services/rest/server"
KIND = "ruleset"
kie_author = require_kie("author")


def failure(status: int, msg: str, headers: dict[str, str] | None = None) -> JSON:
    return JSON(service_response(False, msg), status_code=status, headers=headers)


def kie_failure(request: Request, exc: Exception) -> JSON:
    """The KIE ``FAILURE`` answer for an error raised while serving a KIE endpoint (shared by
    :class:`KieRoute` and the batch's :class:`LeanRoute`)."""
    if isinstance(exc, ApiError):
        return failure(exc.status, exc.message, exc.headers)
    if isinstance(exc, BadBody):
        return failure(exc.status, exc.message)
    if isinstance(exc, RequestValidationError):
        return failure(422, f"invalid request: {exc.errors()}")
    if isinstance(exc, HTTPException):  # e.g. a malformed basic auth header, from FastAPI's reader
        return failure(exc.status_code, str(exc.detail), exc.headers)
    metrics = getattr(request.app.state, "metrics", None)
    if metrics is not None:
        metrics.errors.labels("internal").inc()
    log.error("KIE endpoint %s failed", request.url.path, exc_info=exc)
    return failure(500, f"Unexpected error during processing: {type(exc).__name__}: {exc}")


class KieRoute(APIRoute):
    """Every error under the KIE prefix answers as a KIE ``FAILURE`` body (auth, validation,
    bad bodies and faults included), with the status the module docstring describes."""

    def get_route_handler(self) -> Callable[[Request], Any]:
        handler = super().get_route_handler()

        async def route(request: Request) -> Response:
            try:
                return await handler(request)
            except Exception as exc:
                return kie_failure(request, exc)

        return route


router = APIRouter(prefix=PREFIX, tags=["KIE Server compatible"], route_class=KieRoute)


def check_content_type(request: Request) -> None:
    """JSON only: an XSTREAM/JAXB (XML) client is told so with a 415."""
    kie_type = request.headers.get("x-kie-contenttype", "")
    content_type = request.headers.get("content-type", "")
    if (kie_type and kie_type.strip().upper() != "JSON") or "xml" in content_type.lower():
        raise BadBody(f"this KIE Server speaks JSON only (got X-KIE-ContentType {kie_type or '-'}, Content-Type "
                      f"{content_type or '-'}): send Content-Type: application/json and X-KIE-ContentType: JSON", status=415)


async def read_body(request: Request, *, required: bool = True) -> Any:
    check_content_type(request)
    raw = await request.body()
    if not raw.strip() and not required:
        return None
    try:
        return parse_json(raw, request.app.state.settings.api.max_json_depth)
    except BadBody as bad:
        where = f" (line {bad.extra['line']}, column {bad.extra['column']})" if "line" in bad.extra else ""
        raise BadBody(f"Bad request: {bad.message}{where}", status=bad.status) from None


def _engine(request: Request) -> Any:
    return request.app.state.gateway.engine


# --- server ---------------------------------------------------------------------------------------


@router.get("")
def get_server_info(request: Request, _: Principal = Depends(kie_caller)) -> JSON:
    """KIE Server info (``kie-server-info``: id, version, capabilities)."""
    check_content_type(request)
    settings = request.app.state.settings.api
    location = str(request.base_url).rstrip("/") + PREFIX
    return JSON(service_response(True, "Kie Server info", {"kie-server-info": server_info(settings.server_id, location)}))


@router.get("/readycheck")
def readycheck(request: Request) -> Response:
    """200 once the gateway serves (every current rule set compiled, as at start); 503 before."""
    health = request.app.state.gateway.health()
    ok = health["engine"]["status"] == "ok"
    return Response("" if ok else "not ready", status_code=200 if ok else 503, media_type="text/plain")


@router.get("/healthcheck")
def healthcheck(request: Request, report: bool = False) -> Response:
    """200 when every part of this gateway works (engine, Information State…), else 503;
    ``?report=true`` lists KIE ``Message``s per part."""
    health = request.app.state.gateway.health()
    messages = []
    failed = False
    for part, state in health.items():
        status = state.get("status", "ok")
        bad = status in ("down", "degraded") if part in ("engine", "store") else status == "down"
        failed = failed or bad
        messages.append({"severity": "ERROR" if bad else ("WARN" if status == "degraded" else "INFO"),
                         "timestamp": {"java.util.Date": int(time.time() * 1000)},
                         "content": [f"{part}: {status}" + (f" ({state['error']})" if state.get("error") else "")]})
    status_code = 503 if failed else 200
    if report:
        return JSON(messages, status_code=status_code)
    return Response("", status_code=status_code, media_type="text/plain")


# --- containers -----------------------------------------------------------------------------------


def _sessions_of(engine: Any, name: str) -> list[dict[str, Any]] | None:
    try:
        return engine.declared_sessions(name).to_list()
    except EngineError:
        return None


@router.get("/containers")
def list_containers(request: Request, groupId: str | None = None, artifactId: str | None = None,
                    version: str | None = None, status: str | None = None, _: Principal = Depends(kie_caller)) -> JSON:
    """Every rule set as a ``kie-container`` (status STARTED), filtered like KIE Server."""
    check_content_type(request)
    engine = _engine(request)
    out = []
    for info in engine.list_rulesets():
        rid = release_id(info.name, info.version)
        if (groupId and groupId != rid["group-id"]) or (artifactId and artifactId != info.name) \
                or (version and version != rid["version"]) or (status and "STARTED" not in status.upper().split(",")):
            continue
        out.append(container_resource(info, sessions=_sessions_of(engine, info.name)))
    return JSON(service_response(True, "List of created containers", {"kie-containers": {"kie-container": out}}))


@router.get("/containers/{container_id}")
def get_container(container_id: str, request: Request, _: Principal = Depends(kie_caller)) -> JSON:
    """One rule set as a ``kie-container``; FAILURE (200, as KIE) if none is served by that name."""
    check_content_type(request)
    engine = _engine(request)
    try:
        info = engine.current(container_id).info
    except EngineError:
        return JSON(service_response(False, f"Container {container_id} is not instantiated."))
    return JSON(service_response(True, f"Info for container {container_id}",
                                 {"kie-container": container_resource(info, sessions=_sessions_of(engine, container_id))}))


def _version_for(engine: Any, name: str, wanted: str | int) -> int:
    if wanted == LATEST:
        return max(i.version for i in engine.versions(name))
    engine.version(name, int(wanted))  # VersionNotFound
    return int(wanted)


@router.put("/containers/{container_id}", status_code=201)
async def create_container(container_id: str, request: Request, who: Principal = Depends(kie_author)) -> JSON:
    """Serve a stored version of rule set ``container_id`` (``release-id.version``: a number or
    LATEST): 201; FAILURE 400 if it is served already, or there is no such rule set or version."""
    body = await read_body(request)
    engine = _engine(request)
    try:
        wanted = parse_release_id(body.get("release-id") if isinstance(body, dict) else body, container_id)
    except ReleaseIdError as exc:
        return failure(400, f"Failed to create container {container_id}: {exc}")
    if isinstance(body, dict) and body.get("container-id") not in (None, container_id):
        return failure(400, f"Failed to create container {container_id}: the body's container-id "
                            f"{body.get('container-id')!r} is not the one in the URL")

    def work() -> JSON:
        head = engine.catalog.head(KIND, container_id)
        if head is None:
            return failure(400, f"Failed to create container {container_id} with module "
                                f"{external_release_id(container_id, wanted)}: no rule set named {container_id} is stored; "
                                f"deploy its files first (PUT /api/rulesets/{container_id})")
        if head.live:
            current = engine.current(container_id).info
            return JSON(service_response(False, f"Container {container_id} already exists.",
                                         {"kie-container": container_resource(current)}), status_code=400)
        try:
            target = _version_for(engine, container_id, wanted)
        except (VersionNotFound, RuleSetNotFound):
            return failure(400, f"Failed to create container {container_id} with module "
                                f"{external_release_id(container_id, wanted)}: no such version is stored")
        info = engine.rollback(container_id, target, author=who.name,
                               comment=f"KIE: container created with version {target}", role=who.role)
        return JSON(service_response(True, f"Container {container_id} successfully deployed with module "
                                           f"{external_release_id(container_id, info.version)}.",
                                     {"kie-container": container_resource(info, sessions=_sessions_of(engine, container_id))}),
                    status_code=201)

    return await run_blocking(work)


@router.delete("/containers/{container_id}")
def dispose_container(container_id: str, request: Request, who: Principal = Depends(kie_author)) -> JSON:
    """Stop serving the rule set and dispose its sessions (in every process); its versions and
    history stay, so ``PUT`` can bring it back."""
    check_content_type(request)
    try:
        _engine(request).delete(container_id, author=who.name)
    except EngineError:
        return JSON(service_response(True, f"Container {container_id} was not instantiated."))
    return JSON(service_response(True, f"Container {container_id} successfully disposed."))


@router.get("/containers/{container_id}/release-id")
def get_release_id(container_id: str, request: Request, _: Principal = Depends(kie_caller)) -> JSON:
    check_content_type(request)
    try:
        info = _engine(request).current(container_id).info
    except EngineError:
        return JSON(service_response(False, f"Container {container_id} is not instantiated."))
    return JSON(service_response(True, f"ReleaseId for container {container_id}",
                                 {"release-id": release_id(info.name, info.version)}))


@router.post("/containers/{container_id}/release-id")
async def update_release_id(container_id: str, request: Request, who: Principal = Depends(kie_author)) -> JSON:
    """Move the container to another stored version (a number or LATEST). Its live sessions follow
    as the deploy policy says (``sessions.on_deploy``)."""
    body = await read_body(request)
    engine = _engine(request)
    try:
        wanted = parse_release_id(body, container_id)
    except ReleaseIdError as exc:
        return JSON(service_response(False, f"Error updating release id on container {container_id}: {exc}"))

    def work() -> JSON:
        try:
            current = engine.current(container_id).info
        except EngineError:
            return JSON(service_response(False, f"Container {container_id} is not instantiated."))
        try:
            target = _version_for(engine, container_id, wanted)
        except (VersionNotFound, RuleSetNotFound):
            return JSON(service_response(False, f"Error updating release id on container {container_id} to "
                                                f"{external_release_id(container_id, wanted)}: no such version is stored",
                                         {"release-id": release_id(container_id, current.version)}))
        info = current
        if target != current.version:
            info = engine.rollback(container_id, target, role=who.role, author=who.name,
                                   comment=f"KIE: release id updated to version {target}")
        return JSON(service_response(True, "Release id successfully updated.",
                                     {"release-id": release_id(container_id, info.version)}))

    return await run_blocking(work)


# --- command batches ------------------------------------------------------------------------------

BATCH_SCHEMA: dict[str, Any] = {
    "requestBody": {
        "required": True,
        "content": {"application/json": {"schema": {
            "type": "object",
            "properties": {"lookup": {"type": ["string", "null"]}, "commands": {"type": "array", "items": {"type": "object"}}},
        }}},
    }
}


async def execute(container_id: str, request: Request, _: Principal = Depends(kie_caller)) -> Response:
    """Run a command batch on the session its ``lookup`` names (see the module docstring). It runs
    on the container's own threads (its bulkhead): a FAILURE 429 when its queue is full
    (``api.max_queue``), 503 when it would wait longer than ``api.max_wait_s``, both with
    ``Retry-After``; 503 when a fire runs past ``engine.fire_timeout_s``."""
    body = await read_body(request)
    state = request.app.state
    engine = _engine(request)
    metrics = state.metrics
    try:
        batch = parse_batch(body)
    except BatchError as exc:
        return failure(400 if exc.index < 0 else 422, f"Error calling container {container_id}: {exc}")
    start = time.perf_counter()
    try:
        engine.live_compiled(container_id)  # RuleSetNotFound before a bulkhead is made for the name
        session_id, answer = await state.bulkheads.of(container_id).run(lambda: _run_batch(engine, container_id, batch))
    except Overloaded as exc:
        metrics.fire_error(container_id, exc)
        return failure(exc.status, f"Error calling container {container_id}: {exc}", retry_after(exc))
    except SessionElsewhere as elsewhere:
        try:
            return await forward(request, elsewhere)
        except SessionGone as gone:
            if engine.session_manager.log is None:
                return failure(410, f"Error calling container {container_id}: {gone}")
            return await execute(container_id, request, _)  # a durable session: rebuilt here, or forwarded to its taker
        except OwnerUnreachable as exc:
            return failure(503, f"Error calling container {container_id}: {exc}")
        except Misdirected as exc:
            return failure(421, f"Error calling container {container_id}: {exc}")
    except RuleSetNotFound:
        return failure(404, f"Container {container_id} is not instantiated.")
    except CommandFailed as exc:
        if exc.kind == "timeout":  # halted by engine.fire_timeout_s
            metrics.timeouts.labels(container_id).inc()
        metrics.fire_failed(container_id)
        metrics.errors.labels("kie_failure").inc()
        return failure(command_failed_status(exc), f"Error calling container {container_id}: {_failed(batch, exc)}")
    except SessionGone as gone:
        return failure(410, f"Error calling container {container_id}: {gone}")
    except (Rebuilding, NotYetShared) as exc:
        return failure(503, f"Error calling container {container_id}: {exc}", retry_after(exc))
    except (RebuildFailed, JournalRefused) as exc:
        return failure(exc.status if isinstance(exc, RebuildFailed) else 503,
                       f"Error calling container {container_id}: {exc}")
    except SessionNotFound as exc:
        return failure(404, str(exc))
    except SessionLimit as exc:
        return failure(429, f"Error calling container {container_id}: {exc}")
    except EngineError as exc:
        metrics.fire_failed(container_id)
        return failure(422, f"Error calling container {container_id}: {exc}")
    fired = answer.fired()
    metrics.observe_fire(container_id, time.perf_counter() - start, len(fired))
    marshal = Marshal(engine.type_names(container_id))
    payload = execution_results(batch, answer.results, marshal)
    headers = {"X-Ruleset-Version": str(answer.version),
               "X-KIE-ConversationId": request.headers.get("x-kie-conversationid")
               or conversation_id(state.settings.api.server_id, container_id, answer.version)}
    if session_id:
        headers["X-Session-Id"] = session_id
    decision_id = engine.recorder.batch(container_id, answer, batch.inserted_facts(), origin="kie",
                                        correlation_id=correlation_id(request),
                                        context={"lookup": batch.lookup, "session": session_id})
    if decision_id is not None:
        payload["results"].append({"key": "actions", "value": answer.actions()})
        payload["results"].append({"key": "decision-id", "value": decision_id})
        headers["X-Decision-Id"] = decision_id
    return JSON(service_response(True, f"Container {container_id} successfully called.", {"execution-results": payload}),
                headers=headers)


async def _batch_arguments(request: Request) -> dict[str, Any]:
    """The batch endpoint's arguments, as FastAPI would solve them: the container id, the caller."""
    return {"container_id": request.path_params["container_id"], "request": request,
            "_": await check_kie(request, "caller")}


BATCH_ROUTE = LeanRoute(PREFIX + "/containers/instances/{container_id}", execute, prepare=_batch_arguments,
                        on_error=kie_failure, methods=["POST"], tags=["KIE Server compatible"],
                        openapi_extra=BATCH_SCHEMA)


def _run_batch(engine: Any, container_id: str, batch: Batch) -> tuple[str | None, Any]:
    """Runs ``batch`` on its session: the live one of a stateful lookup, or a fresh stateless one
    (which, as KIE's stateless sessions do, fires at the end unless the batch fires itself)."""
    engine.live_compiled(container_id)  # RuleSetNotFound before anything else
    declared, session = engine.session_manager.lookup(container_id, batch.lookup)
    commands = batch.commands
    if session is not None:
        return session.id, session.execute(commands)
    if not batch.fires:
        commands = commands + [{"op": "fire", "max": -1}]
    temp = engine.new_session(container_id, declared.name, clock=declared.clock, on_deploy="pin", kind="kie",
                              record_facts=True, on_close=None)
    try:
        return None, temp.execute(commands)
    finally:
        temp.close()


def _failed(batch: Batch, exc: CommandFailed) -> str:
    """The failure in KIE's terms: the KIE command's index and name, and what happened to the session."""
    name = batch.steps[exc.index].name if 0 <= exc.index < len(batch.steps) else exc.op or "fire-all-rules"
    index = exc.index if exc.index < len(batch.steps) else len(batch.steps)
    outcome = ("the session was rolled back to before the batch (a durable session is rebuilt from its log)"
               if exc.rolled_back else
               "the commands before it were applied (as in KIE Server, rules that fired are not undone)"
               if exc.applied else "nothing was executed: the session is as it was")
    where = f"command {index} ({name})" if exc.index >= 0 else "the batch"
    return f"{where}: {exc.detail}; {outcome}"


# --- anything else under the prefix -----------------------------------------------------------------


@router.api_route("/{rest:path}", methods=["GET", "POST", "PUT", "DELETE", "PATCH"], include_in_schema=False)
def not_supported(rest: str, request: Request) -> JSON:
    """KIE endpoints this gateway does not offer (processes, tasks, DMN, scanners, …)."""
    first = rest.split("/")[0]
    what = "processes, tasks and jobs are not supported (this gateway runs rules: KIE Server's BRM capability)" \
        if first in ("queries", "admin", "jobs") or "process" in rest or "tasks" in rest \
        else f"{request.method} {PREFIX}/{rest} is not a KIE Server endpoint of this gateway"
    return failure(404, f"{what}; supported: server info, readycheck, healthcheck, containers (list, get, PUT, DELETE, "
                        "release-id) and containers/instances/{id} command batches")
