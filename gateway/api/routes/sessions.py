"""``/api/rulesets/{name}/sessions``: stateful sessions over REST — the same sessions a KIE
``lookup`` reaches (see :mod:`gateway.engine.sessions`).

A session keeps its facts between calls; facts are addressed by their fact handles (KIE's
external form, ``0:id:…``, returned by an insert); the session's clock is a pseudo clock moved by
``advance`` (or by an insert's ``timestamp``) unless it was opened with ``"clock": "realtime"``;
every ``fire`` is a recorded decision (origin ``rest``). A session lives in the gateway process
that holds it: a call that reaches another process is forwarded to it (see
:mod:`gateway.api.forwarding`); if that process is gone, a durable session (the default) is
rebuilt where the call landed, one that is not durable answers 410.
"""

from __future__ import annotations

import time
from typing import Annotated, Any, Callable, Literal

from fastapi import APIRouter, Query, Request
from fastapi import Path as PathParam
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field

from gateway.api.deps import Caller, EngineDep, correlation_id
from gateway.api.errors import ApiError
from gateway.api.forwarding import Misdirected, OwnerUnreachable, forward
from gateway.api.jsonio import JSON, JsonRoute, run_blocking
from gateway.api.routes.rulesets import NAME_PATTERN, check_facts
from gateway.engine import EngineError
from gateway.engine.errors import Overloaded
from gateway.engine.sessions import SessionElsewhere, SessionGone, SessionNotFound

RuleSetName = Annotated[str, PathParam(pattern=NAME_PATTERN, description="Rule set name")]
SessionId = Annotated[str, PathParam(min_length=1, max_length=128, description="Session id (a declared ksession's name, or "
                                                                                 "the id a create returned)")]
Handle = Annotated[str, PathParam(min_length=3, max_length=400, description="A fact handle (KIE's external form 0:id:…)")]

router = APIRouter(tags=["sessions"], route_class=JsonRoute)


#: A fact: ``{"type": <a declared type>, <its fields>…}``. Checked by :func:`check_facts`, not by pydantic,
#: so a fact without a type is refused in the fire route's shape (422 ``kind: "facts"``, with its index).
FACT_SCHEMA = {"type": "object", "required": ["type"], "additionalProperties": True,
               "properties": {"type": {"type": "string", "minLength": 1,
                                       "description": "A type the rule set declares; the other fields are its fields"}}}
Fact = Annotated[Any, Field(json_schema_extra=FACT_SCHEMA)]


class CreateBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    id: str | None = Field(default=None, min_length=1, max_length=128,
                           description="A declared stateful ksession's name (the session KIE's lookup reaches) or an id "
                                       "of your own; default: a generated one")
    clock: Literal["pseudo", "realtime"] | None = Field(default=None, description="default: the ksession's, else pseudo")
    on_deploy: Literal["follow", "pin"] | None = Field(
        default=None, description="On a new deploy: move with the facts (follow) or stay (pin); default: sessions.on_deploy")
    facts: list[Fact] = Field(default_factory=list, max_length=100_000, description="Facts to insert at once")
    durable: bool | None = Field(default=None, description="Outlive this process: journalled, rebuilt elsewhere after "
                                 "a crash (default: sessions.durable)")


class InsertBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    facts: list[Fact] = Field(min_length=1, max_length=100_000)
    timestamp: int | None = Field(default=None, ge=0, description="Move the pseudo clock to this time (ms) first")
    entry_point: str = Field(default="DEFAULT", min_length=1, max_length=200)
    fire: bool = Field(default=False, description="Fire afterwards, in the same call (a decision)")


class ModifyBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    set: dict[str, Any] = Field(min_length=1, description="field -> new value")


class UpdateBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    fact: Fact


class FireBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    max: int = Field(default=-1, ge=-1, description="Fire at most this many rules (-1: all, with the runaway guard)")


class AdvanceBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    ms: int | None = Field(default=None, ge=0, description="Move the pseudo clock forward by this much")
    to: int | None = Field(default=None, ge=0, description="... or to this time (ms; never back)")
    fire: bool = Field(default=False, description="Fire afterwards (what the time made due: windows, after[...])")


def _facts(facts: list[Any]) -> list[dict[str, Any]]:
    """The facts as the engine takes them, or FactError 422 (``kind: "facts"``) naming the bad one."""
    check_facts(facts)
    return facts


async def _on_ruleset_threads(request: Request, fn: Callable[..., Any], *args: Any) -> Any:
    """Runs ``fn`` on the rule set's own threads (its bulkhead: a session's fires are held to the
    same queue, wait and refusals as the rule set's other fires), or on the shared pool when no
    such rule set is live (``fn`` then answers why)."""
    name = request.path_params.get("name")
    state = request.app.state
    try:
        state.engine.live_compiled(name)
    except EngineError:
        return await run_blocking(fn, *args)
    try:
        return await state.bulkheads.of(name).run(lambda: fn(*args))
    except Overloaded as exc:
        state.metrics.fire_error(name, exc)
        raise


async def _at_owner(request: Request, fn: Callable[..., Any], *args: Any) -> Any:
    """Runs ``fn`` here, or forwards the request to the process that owns the session. An owner
    found gone while forwarding (its record released) leaves a durable session to be rebuilt here:
    the call is run again, once."""
    try:
        return await _on_ruleset_threads(request, fn, *args)
    except SessionElsewhere as elsewhere:
        try:
            return await forward(request, elsewhere)
        except SessionGone as gone:
            if request.app.state.engine.session_manager.log is not None:
                try:
                    return await _here_after_owner_gone(request, fn, *args)
                except SessionNotFound:  # it was not durable: lost with its process
                    pass
            raise ApiError(410, str(gone), session=elsewhere.session_id, owner=elsewhere.owner.get("process")) from None
        except OwnerUnreachable as exc:
            raise ApiError(503, str(exc), headers={"Retry-After": "1"}) from None
        except Misdirected as exc:
            raise ApiError(421, str(exc)) from None


async def _here_after_owner_gone(request: Request, fn: Callable[..., Any], *args: Any) -> Any:
    try:
        return await _on_ruleset_threads(request, fn, *args)
    except SessionElsewhere as elsewhere:  # another process took it over first: it answers
        return await forward(request, elsewhere)


def _info(engine: Any, session: Any) -> dict[str, Any]:
    out = session.to_dict()
    directory = engine.session_manager.directory
    out["process"] = directory.process if directory is not None else None
    return out


@router.get("/api/rulesets/{name}/sessions")
def list_sessions(name: RuleSetName, engine: EngineDep, _: Caller) -> JSON:
    """The rule set's open sessions: this process's (with their clock and fact count, and for a
    durable one ``durable``, ``last_snapshot``, ``commands_since_snapshot``), those other gateway
    processes hold (their owner), durable ones no process holds now (``stored``: rebuilt on their
    next call), plus the ksessions the rule set declares."""
    engine.live_compiled(name)  # 404 for an unknown rule set
    manager = engine.session_manager
    here = [_info(engine, s) for s in manager.list(name) if s.kind != "stream"]
    elsewhere = []
    if manager.directory is not None:
        local = {s["id"] for s in here}
        members = getattr(manager.directory, "members", None)
        for record in manager.directory.records(name):
            if record["session"] in local or record["process"] == manager.directory.process:
                continue
            alive = members.alive(members.get(record["process"])) if members is not None else None
            elsewhere.append({"id": record["session"], "ruleset": name, "process": record["process"], "kind": record.get("kind"),
                              "clock": record.get("clock"), "on_deploy": record.get("on_deploy"), "owner_alive": alive})
    return JSON({"sessions": here + elsewhere + _stored_only(manager, name, here + elsewhere),
                 "declared": engine.declared_sessions(name).to_list()})


def _stored_only(manager: Any, name: str, listed: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Durable sessions no process holds now (after a restart, or their owner died): rebuilt on
    their next call."""
    if manager.log is None:
        return []
    known = {s["id"] for s in listed}
    return [{"id": o["session"], "ruleset": name, "process": None, "kind": o.get("session_kind"), "clock": o.get("clock"),
             "on_deploy": o.get("on_deploy"), "durable": True, "stored": True}
            for o in manager.log.sessions(name) if o["session"] not in known]


@router.post("/api/rulesets/{name}/sessions", status_code=201)
async def create_session(name: RuleSetName, body: CreateBody, request: Request, engine: EngineDep, _: Caller) -> Response:
    """Open a stateful session: 201 ``{"id", "version", "clock", "time", "fact_count", …}`` (with
    ``handles`` for the ``facts`` inserted). Naming a declared ksession that is open already
    returns it (200, the ``facts`` inserted into it); any other id already open: 409, nothing changes."""
    manager = engine.session_manager

    def work() -> JSON:
        engine.live_compiled(name)
        if body.id is not None:
            existing = manager.find(name, body.id)
            declared = engine.declared_sessions(name).get(body.id)
            if existing is None and declared is not None and declared.stateful:
                existing = manager.get(name, body.id)  # elsewhere, or made on first use like a KIE lookup
                if body.facts:
                    return _created(engine, existing, body, 201)
                return JSON(_info(engine, existing), status_code=201)
            if existing is not None and declared is not None and declared.stateful:
                return _created(engine, existing, body, 200)  # the live ksession, with the facts sent inserted
            if manager.directory is not None:  # an id another process holds
                owner = manager.directory.owner(name, body.id)
                if owner is not None and owner.get("process") != manager.directory.process:
                    raise SessionElsewhere(name, body.id, owner)
        session = manager.open(name, session_id=body.id, kind="rest", clock=body.clock, on_deploy=body.on_deploy,
                               durable_=body.durable)
        return _created(engine, session, body, 201)

    return await _at_owner(request, work)


def _created(engine: Any, session: Any, body: CreateBody, status: int) -> JSON:
    out = _info(engine, session)
    if body.facts:
        try:
            answer = session.execute([{"op": "insert", "facts": _facts(body.facts), "ep": "DEFAULT"}])
        except Exception:
            if status == 201 and session.kind == "rest":
                session.close()  # a refused create leaves nothing behind
            raise
        out["handles"] = answer.results[0]["handles"]
        out["fact_count"] = answer.fact_count
    return JSON(out, status_code=status, headers={"Location": f"/api/rulesets/{session.ruleset}/sessions/{session.id}"})


@router.get("/api/rulesets/{name}/sessions/{session_id}")
async def get_session(name: RuleSetName, session_id: SessionId, request: Request, engine: EngineDep, _: Caller) -> Response:
    """A session: version, clock (``time``), ``fact_count``, policy, idle time, moves to new versions."""
    return await _at_owner(request, lambda: JSON(_info(engine, engine.session_manager.get(name, session_id))))


@router.delete("/api/rulesets/{name}/sessions/{session_id}")
async def dispose_session(name: RuleSetName, session_id: SessionId, request: Request, engine: EngineDep, _: Caller) -> Response:
    """Dispose the session (its facts go)."""
    def work() -> JSON:
        engine.session_manager.dispose(name, session_id)
        return JSON({"id": session_id, "ruleset": name, "disposed": True})

    return await _at_owner(request, work)


@router.get("/api/rulesets/{name}/sessions/{session_id}/facts")
async def read_facts(name: RuleSetName, session_id: SessionId, request: Request, engine: EngineDep, _: Caller,
                     type: Annotated[str | None, Query(description="Only facts of this declared type")] = None) -> Response:
    """The session's facts with their handles: ``{"facts": [{"handle", "fact"}], "time", "fact_count"}``."""
    def work() -> JSON:
        session = engine.session_manager.get(name, session_id)
        answer = session.execute([{"op": "get_objects", "type": type, "handles": True}])
        return JSON({"facts": answer.results[0]["value"], "time": answer.time, "fact_count": answer.fact_count,
                     "version": answer.version})

    return await _at_owner(request, work)


@router.post("/api/rulesets/{name}/sessions/{session_id}/facts", status_code=201)
async def insert_facts(name: RuleSetName, session_id: SessionId, body: InsertBody, request: Request, engine: EngineDep,
                       _: Caller) -> Response:
    """Insert facts (events with a ``timestamp`` move the pseudo clock there first): 201
    ``{"handles": [...], "time", "fact_count"}``; 422 naming the fact and field, nothing inserted.
    With ``"fire": true`` the session fires in the same call: the answer is also the decision
    (``decision_id``, ``actions``, ``fired``…), as from ``…/fire``."""
    commands: list[dict[str, Any]] = []
    if body.timestamp is not None:
        commands.append({"op": "advance_to", "to": body.timestamp})
    commands.append({"op": "insert", "facts": _facts(body.facts), "ep": body.entry_point})
    if body.fire:
        commands.append({"op": "fire", "max": -1})
        return await _at_owner(request, _fire, engine, name, session_id, commands, correlation_id(request), 201)

    def work() -> JSON:
        session = engine.session_manager.get(name, session_id)
        answer = session.execute(commands)
        return JSON({"handles": answer.results[-1]["handles"], "time": answer.time, "fact_count": answer.fact_count,
                     "version": answer.version}, status_code=201)

    return await _at_owner(request, work)


@router.patch("/api/rulesets/{name}/sessions/{session_id}/facts/{handle}")
async def modify_fact(name: RuleSetName, session_id: SessionId, handle: Handle, body: ModifyBody, request: Request,
                      engine: EngineDep, _: Caller) -> Response:
    """Set fields of a fact (KIE's ``modify``): ``{"handle", "fact"}`` as it is now."""
    def work() -> JSON:
        session = engine.session_manager.get(name, session_id)
        answer = session.execute([{"op": "modify", "handle": handle, "set": [[k, v] for k, v in body.set.items()]},
                                  {"op": "get_object", "handle": handle}])
        return JSON({"handle": handle, "fact": answer.results[1]["value"], "version": answer.version})

    return await _at_owner(request, work)


@router.put("/api/rulesets/{name}/sessions/{session_id}/facts/{handle}")
async def update_fact(name: RuleSetName, session_id: SessionId, handle: Handle, body: UpdateBody, request: Request,
                      engine: EngineDep, _: Caller) -> Response:
    """Replace a fact (KIE's ``update``): ``{"handle", "fact"}``."""
    def work() -> JSON:
        session = engine.session_manager.get(name, session_id)
        answer = session.execute([{"op": "update", "handle": handle, "fact": _facts([body.fact])[0]},
                                  {"op": "get_object", "handle": handle}])
        return JSON({"handle": handle, "fact": answer.results[1]["value"], "version": answer.version})

    return await _at_owner(request, work)


@router.delete("/api/rulesets/{name}/sessions/{session_id}/facts/{handle}")
async def retract_fact(name: RuleSetName, session_id: SessionId, handle: Handle, request: Request, engine: EngineDep,
                       _: Caller) -> Response:
    """Retract a fact by its handle; 422 if the handle is stale."""
    def work() -> JSON:
        session = engine.session_manager.get(name, session_id)
        answer = session.execute([{"op": "delete", "handle": handle}])
        return JSON({"retracted": handle, "fact_count": answer.fact_count})

    return await _at_owner(request, work)


@router.post("/api/rulesets/{name}/sessions/{session_id}/fire")
async def fire_session(name: RuleSetName, session_id: SessionId, request: Request, engine: EngineDep, _: Caller,
                       body: FireBody | None = None) -> Response:
    """Fire what the session's facts activate (at most ``max``): a recorded decision,
    ``{"decision_id", "version", "actions", "fired", "fire_count", "time", "fact_count", …}``."""
    fire_max = body.max if body is not None else -1
    return await _at_owner(request, _fire, engine, name, session_id, [{"op": "fire", "max": fire_max}],
                           correlation_id(request))


@router.post("/api/rulesets/{name}/sessions/{session_id}/advance")
async def advance_clock(name: RuleSetName, session_id: SessionId, body: AdvanceBody, request: Request, engine: EngineDep,
                        _: Caller) -> Response:
    """Move the session's pseudo clock (``ms`` forward, or ``to`` a time): ``{"time"}``; with
    ``"fire": true`` also fire, as a decision. 422 for a realtime session."""
    if (body.ms is None) == (body.to is None):
        raise ApiError(422, "give exactly one of 'ms' (move forward by) and 'to' (move to a time)",
                       errors=[{"field": "ms", "message": "one of ms, to"}])
    command = {"op": "advance", "ms": body.ms} if body.ms is not None else {"op": "advance_to", "to": body.to}
    if body.fire:
        return await _at_owner(request, _fire, engine, name, session_id, [command, {"op": "fire", "max": -1}],
                               correlation_id(request))

    def work() -> JSON:
        answer = engine.session_manager.get(name, session_id).execute([command])
        return JSON({"time": answer.time, "fact_count": answer.fact_count, "version": answer.version})

    return await _at_owner(request, work)


def _fire(engine: Any, name: str, session_id: str, commands: list[dict[str, Any]], correlation: str | None,
          status: int = 200) -> JSON:
    session = engine.session_manager.get(name, session_id)
    started = time.perf_counter()
    answer = session.execute(commands)
    result = engine.recorder.session_fire(name, commands, answer, duration_ms=(time.perf_counter() - started) * 1000,
                                          origin="rest", correlation_id=correlation,
                                          context={"session": session_id, "fact_count": answer.fact_count})
    out = result.to_dict()
    out.pop("facts", None)
    out.update({"session": session_id, "time": answer.time, "fact_count": answer.fact_count})
    handles = [h for r in answer.results if r["op"] == "insert" for h in r.get("handles", [])]
    if handles:
        out["handles"] = handles
    return JSON(out, status_code=status)
