"""KIE Server 7.x compatible endpoints, so existing KIE Server clients work unchanged.

``/kie-server/services/rest/server`` (server info), ``…/containers`` (rule sets as containers, the
container id is the rule set name), ``…/containers/{id}`` and ``POST …/containers/instances/{id}``
with a batch of commands. Answers use KIE Server's ``ServiceResponse`` JSON:
``{"type": "SUCCESS"|"FAILURE", "msg": "...", "result": ...}``. Like KIE Server, a command batch
that cannot be executed (unknown container, bad facts, unsupported command) is answered with HTTP
200 and ``type: FAILURE`` plus a message naming the problem; only a body that is not JSON at all
gets a 4xx.

Translation (plain functions, testable without HTTP): an inserted ``{"org.pkg.Customer": {...}}``
becomes the engine fact ``{"type": "Customer", ...}``; facts going back out get the package they
came in with, else the package the rule set declares them in. Then-part actions are returned as an extra result
with key ``actions``; the serving version is in the ``X-Ruleset-Version`` header.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field
from typing import Any

from fastapi import APIRouter, Depends, Request

from gateway.api.auth import Principal, kie_caller
from gateway.api.deps import correlation_id
from gateway.api.jsonio import JSON, read_json, run_blocking
from gateway.engine import EngineError, FireResult, RuleSetNotFound

PREFIX = "/kie-server/services/rest/server"
KIE_VERSION = "7.74.1.Final"  # the KIE Server API level these answers follow
CAPABILITIES = ["KieServer", "BRM"]
GROUP_ID = "org.printeps.rules"
FACT_HANDLE = "org.drools.core.common.DefaultFactHandle"
SUPPORTED = ("insert", "insert-elements", "fire-all-rules", "get-objects", "set-global", "get-global",
             "query", "dispose")

router = APIRouter(prefix=PREFIX, tags=["KIE Server compatible"])
_handle_ids = itertools.count(1)


class BatchError(Exception):
    """The batch cannot be executed; the message goes into a FAILURE response."""


def service_response(ok: bool, msg: str, result: Any = None) -> dict[str, Any]:
    return {"type": "SUCCESS" if ok else "FAILURE", "msg": msg, "result": result}


def release_id(name: str, version: int) -> dict[str, str]:
    return {"group-id": GROUP_ID, "artifact-id": name, "version": str(version)}


def container_resource(info: Any) -> dict[str, Any]:
    """A rule set version as a ``kie-container`` resource."""
    rid = release_id(info.name, info.version)
    return {
        "container-id": info.name,
        "release-id": rid,
        "resolved-release-id": dict(rid),
        "status": "STARTED",
        "scanner": {"status": "DISPOSED", "poll-interval": None},
        "config-items": [],
        "messages": [
            {
                "severity": "INFO",
                "timestamp": {"java.util.Date": _epoch_ms(info.deployed_at)},
                "content": [f"Container {info.name} version {info.version} deployed by {info.author}"],
            }
        ],
        "container-alias": info.name,
    }


def _epoch_ms(iso: str) -> int:
    from datetime import datetime

    try:
        return int(datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp() * 1000)
    except (ValueError, AttributeError):
        return 0


def server_info(server_id: str, location: str) -> dict[str, Any]:
    return {
        "id": server_id,
        "name": server_id,
        "version": KIE_VERSION,
        "location": location,
        "capabilities": list(CAPABILITIES),
        "messages": [
            {
                "severity": "INFO",
                "timestamp": {"java.util.Date": int(time.time() * 1000)},
                "content": [f"Server {server_id} (PRINTEPS gateway, KIE Server compatible) is running"],
            }
        ],
        "mode": "PRODUCTION",
    }


# --- command batches -------------------------------------------------------------------------


def parse_commands(body: Any) -> list[tuple[str, dict[str, Any]]]:
    """The (name, arguments) of each command of a batch (or of a single bare command)."""
    if not isinstance(body, dict):
        raise BatchError("Bad request, the body must be a JSON object with 'commands'")
    if "commands" in body:
        raw = body["commands"]
    elif len(body) == 1 and next(iter(body)) in SUPPORTED:
        raw = [body]  # KIE Server also accepts one command without a batch around it
    else:
        raise BatchError("Bad request, no commands to be executed - either wrong format or no data")
    if not isinstance(raw, list) or not raw:
        raise BatchError("Bad request, no commands to be executed - either wrong format or no data")
    commands = []
    for index, cmd in enumerate(raw):
        if not isinstance(cmd, dict) or len(cmd) != 1:
            raise BatchError(f"command {index}: expected an object with exactly one command name")
        name, args = next(iter(cmd.items()))
        if name not in SUPPORTED:
            raise BatchError(f"command {index}: '{name}' is not supported (supported: {', '.join(SUPPORTED)})")
        if args is None:
            args = {}
        if not isinstance(args, dict):
            raise BatchError(f"command {index} ({name}): its arguments must be an object")
        commands.append((name, args))
    return commands


def fact_from_kie(obj: Any, where: str, packages: dict[str, str]) -> dict[str, Any]:
    """``{"org.pkg.Customer": {...}}`` -> ``{"type": "Customer", ...}``; remembers the package."""
    if not isinstance(obj, dict) or len(obj) != 1:
        raise BatchError(f"{where}: the object must be {{\"<package>.<Type>\": {{fields}}}}")
    fqcn, fields = next(iter(obj.items()))
    if not isinstance(fields, dict):
        raise BatchError(f"{where}: the fields of {fqcn} must be an object")
    if "type" in fields:
        raise BatchError(f"{where}: the field name 'type' is reserved by the gateway")
    package, _, simple = fqcn.rpartition(".")
    if not simple:
        raise BatchError(f"{where}: {fqcn!r} is not a type name")
    if package:
        packages[simple] = package
    return {"type": simple, **fields}


def fact_to_kie(fact: dict[str, Any], packages: dict[str, str], default_package: str) -> dict[str, Any]:
    fields = {k: v for k, v in fact.items() if k != "type"}
    simple = str(fact.get("type", "Object"))
    return {f"{packages.get(simple, default_package)}.{simple}": fields}


def fact_handle(fqcn: str) -> dict[str, Any]:
    n = next(_handle_ids)
    return {FACT_HANDLE: {"external-form": f"0:{n}:{n}:{n}:{n}:DEFAULT:NON_TRAIT:{fqcn}"}}


@dataclass
class BatchRun:
    """State of one batch: what was inserted, what the session holds, what to answer."""

    name: str
    packages: dict[str, str] = field(default_factory=dict)
    pending: list[dict[str, Any]] = field(default_factory=list)
    inserted: list[tuple[dict[str, Any], str | None, bool]] = field(default_factory=list)
    known_facts: list[dict[str, Any]] = field(default_factory=list)
    results: list[dict[str, Any]] = field(default_factory=list)
    facts_out: list[dict[str, Any]] = field(default_factory=list)
    actions: list[Any] = field(default_factory=list)
    fired: list[str] = field(default_factory=list)
    fired_any: bool = False
    version: int | None = None

    @property
    def default_package(self) -> str:
        return next(iter(self.packages.values()), f"org.printeps.{self.name}")


def run_batch(engine: Any, name: str, commands: list[tuple[str, dict[str, Any]]]) -> BatchRun:
    """Execute the commands in order on one stateful session of rule set ``name``."""
    run = BatchRun(name)
    session = engine.open_session(name)
    run.version = session.version
    for simple, fqcn in engine.type_names(name).items():
        run.packages[simple] = fqcn.rpartition(".")[0]
    try:
        for index, (cmd, args) in enumerate(commands):
            where = f"command {index} ({cmd})"
            if cmd == "insert":
                fact = fact_from_kie(args.get("object"), where, run.packages)
                _insert(run, session, [fact], args.get("out-identifier"), bool(args.get("return-object", True)))
            elif cmd == "insert-elements":
                objects = args.get("objects")
                if not isinstance(objects, list):
                    raise BatchError(f"{where}: 'objects' must be a list")
                facts = [fact_from_kie(o, f"{where} object {i}", run.packages) for i, o in enumerate(objects)]
                _insert(run, session, facts, None, False)
                if args.get("out-identifier"):
                    run.results.append({"key": args["out-identifier"], "value": [
                        fact_to_kie(f, run.packages, run.default_package) for f in facts]})
            elif cmd == "fire-all-rules":
                _flush(run, session)
                result = session.fire(return_facts=True)
                _absorb(run, result)
                if args.get("out-identifier"):
                    run.results.append({"key": args["out-identifier"], "value": len(result.fired)})
            elif cmd == "get-objects":
                _flush(run, session)
                wanted = _class_filter(args.get("class-object-filter"))
                objs = [fact_to_kie(f, run.packages, run.default_package) for f in _current_facts(run)
                        if wanted is None or f.get("type") == wanted]
                run.results.append({"key": args.get("out-identifier") or "objects", "value": objs})
            elif cmd == "set-global":
                _flush(run, session)
                identifier = _required(args, "identifier", where)
                _engine_call(where, session.set_global, identifier, _unwrap_object(args.get("object")))
                if args.get("out-identifier"):
                    run.results.append({"key": args["out-identifier"], "value": args.get("object")})
            elif cmd == "get-global":
                identifier = _required(args, "identifier", where)
                value = _engine_call(where, session.get_global, identifier)
                run.results.append({"key": args.get("out-identifier") or identifier, "value": value})
            elif cmd == "query":
                _flush(run, session)
                query_name = _required(args, "name", where)
                arguments = args.get("arguments") or []
                if not isinstance(arguments, list):
                    raise BatchError(f"{where}: 'arguments' must be a list")
                answer = _engine_call(where, session.query, query_name, arguments)
                run.results.append({"key": args.get("out-identifier") or query_name,
                                    "value": flat_query_results(answer, run.packages, run.default_package)})
            elif cmd == "dispose":
                pass
        _flush(run, session)
    finally:
        engine.close_session(session.id)
    _returned_objects(run)
    return run


def _required(args: dict[str, Any], key: str, where: str) -> str:
    value = args.get(key)
    if not isinstance(value, str) or not value:
        raise BatchError(f"{where}: '{key}' is required")
    return value


def _engine_call(where: str, fn: Any, *args: Any) -> Any:
    from gateway.engine import EngineError

    try:
        return fn(*args)
    except EngineError as exc:
        raise BatchError(f"{where}: {exc}") from None


def _unwrap_object(value: Any) -> Any:
    """KIE clients send typed values, ``{"java.lang.Integer": 18}``; plain JSON works too."""
    if isinstance(value, dict) and len(value) == 1:
        key = next(iter(value))
        if "." in key:
            return value[key]
    return value


def flat_query_results(answer: dict[str, Any], packages: dict[str, str], default_package: str) -> dict[str, Any]:
    """A query answer in KIE Server's marshalled ``FlatQueryResults`` shape."""
    def value(v: Any) -> Any:
        return fact_to_kie(v, packages, default_package) if isinstance(v, dict) and "type" in v else v

    rows = [{"element": [{"key": k, "value": value(v)} for k, v in row.items()]} for row in answer["rows"]]
    return {"org.drools.core.runtime.rule.impl.FlatQueryResults": {
        "idFactHandleMaps": {"type": "LIST", "componentType": None, "element": []},
        "idResultMaps": {"type": "LIST", "componentType": None, "element": rows},
        "identifiers": {"type": "SET", "componentType": None, "element": answer["identifiers"]},
    }}


def _insert(run: BatchRun, session: Any, facts: list[dict[str, Any]], out_id: str | None, ret: bool) -> None:
    run.pending.extend(facts)
    for fact in facts:
        run.inserted.append((fact, out_id, ret))


def _flush(run: BatchRun, session: Any) -> None:
    if run.pending:
        session.insert(run.pending)
        run.known_facts.extend(run.pending)
        run.pending = []


def _absorb(run: BatchRun, result: Any) -> None:
    run.fired_any = True
    run.version = result.version
    run.actions.extend(result.actions)
    run.fired.extend(f.get("rule", "?") for f in result.fired)
    run.known_facts = list(result.facts)


def _current_facts(run: BatchRun) -> list[dict[str, Any]]:
    return run.known_facts


def _class_filter(value: Any) -> str | None:
    if isinstance(value, dict):
        value = value.get("string")
    if not isinstance(value, str) or value in ("java.lang.Object", ""):
        return None
    return value.rpartition(".")[2]


def _returned_objects(run: BatchRun) -> None:
    """Inserted objects with an out-identifier: their final state (results) and a fact handle (facts)."""
    by_key = {(f.get("type"), f.get("id")): f for f in run.known_facts if f.get("id") is not None}
    for fact, out_id, ret in run.inserted:
        if not out_id:
            continue
        final = by_key.get((fact.get("type"), fact.get("id")), fact) if fact.get("id") is not None else fact
        kie = fact_to_kie(final, run.packages, run.default_package)
        if ret:
            run.results.append({"key": out_id, "value": kie})
        run.facts_out.append({"key": out_id, "value": fact_handle(next(iter(kie)))})


# --- routes ----------------------------------------------------------------------------------


@router.get("")
def get_server_info(request: Request, _: Principal = Depends(kie_caller)) -> JSON:
    """KIE Server info (``kie-server-info``: id, version, capabilities)."""
    settings = request.app.state.settings.api
    location = str(request.base_url).rstrip("/") + PREFIX
    return JSON(service_response(True, "Kie Server info", {"kie-server-info": server_info(settings.server_id, location)}))


@router.get("/containers")
def list_containers(request: Request, _: Principal = Depends(kie_caller)) -> JSON:
    """Every rule set as a ``kie-container`` (status STARTED)."""
    infos = request.app.state.engine.list_rulesets()
    return JSON(service_response(True, "List of created containers",
                                 {"kie-containers": {"kie-container": [container_resource(i) for i in infos]}}))


@router.get("/containers/{container_id}")
def get_container(container_id: str, request: Request, _: Principal = Depends(kie_caller)) -> JSON:
    """One rule set as a ``kie-container``; FAILURE if there is none of that name."""
    try:
        info = request.app.state.engine.current(container_id).info
    except RuleSetNotFound:
        return JSON(service_response(False, f"Container {container_id} is not instantiated."))
    return JSON(service_response(True, f"Info for container {container_id}", {"kie-container": container_resource(info)}))


BATCH_SCHEMA: dict[str, Any] = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {
                "schema": {
                    "type": "object",
                    "properties": {
                        "lookup": {"type": ["string", "null"]},
                        "commands": {"type": "array", "items": {"type": "object"}},
                    },
                }
            }
        },
    }
}


@router.post("/containers/instances/{container_id}", openapi_extra=BATCH_SCHEMA)
async def execute(container_id: str, request: Request, _: Principal = Depends(kie_caller)) -> JSON:
    """Run a command batch (insert, insert-elements, fire-all-rules, get-objects, dispose)."""
    body = await read_json(request)
    metrics = request.app.state.metrics
    engine = request.app.state.engine
    try:
        commands = parse_commands(body)
        start = time.perf_counter()
        run = await run_blocking(run_batch, engine, container_id, commands)
    except RuleSetNotFound:
        return JSON(service_response(False, f"Container {container_id} is not instantiated."))
    except (BatchError, EngineError) as exc:
        metrics.fire_failed(container_id)
        metrics.errors.labels("kie_failure").inc()
        return JSON(service_response(False, f"Error calling container {container_id}: {exc}"))
    metrics.observe_fire(container_id, time.perf_counter() - start, len(run.fired))
    results = list(run.results)
    headers = {"X-Ruleset-Version": str(run.version)} if run.version is not None else {}
    if run.fired_any:
        decision = FireResult(container_id, run.version or 0, run.actions, [{"rule": r} for r in run.fired],
                              fire_count=len(run.fired))
        decision_id = engine.record_decision(decision, [f for f, _, _ in run.inserted], origin="kie",
                                             correlation_id=correlation_id(request),
                                             context={"lookup": body.get("lookup") if isinstance(body, dict) else None})
        results.append({"key": "actions", "value": run.actions})
        results.append({"key": "decision-id", "value": decision_id})
        headers["X-Decision-Id"] = decision_id
    payload = {"execution-results": {"results": results, "facts": run.facts_out}}
    return JSON(service_response(True, f"Container {container_id} successfully called.", payload), headers=headers)
