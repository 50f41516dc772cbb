"""REST for stream reasoning: continuous queries, stream input, results (also live), and SWRL reasoning.

Why a services object: the router is a thin edge; the C-SPARQL engine, the message mapper and the
Pellet reasoner are built once at start-up (``build_services``) and handed over with
``configure(services)`` (or put on ``app.state.stream_services``). Without them every route answers
503 rather than guessing.

    POST   /api/queries                 C-SPARQL (text/plain, or JSON {"query", "params", "replace", "rules"})
    GET    /api/queries                 registered queries with their counters
    GET    /api/queries/{name}          one query
    DELETE /api/queries/{name}
    PUT    /api/queries/{name}/rules    {"ruleset", "fact_type", "fields", "mode"} — rows become facts
    DELETE /api/queries/{name}/rules
    GET    /api/queries/{name}/results  recent non-empty results (?limit=)
    GET    /api/queries/{name}/live     Server-Sent Events: result / actions / error events
    GET    /api/streams/live            the same for all queries
    POST   /api/streams                 {"stream", "timestamp", "triples": [[s,p,o], …]} or
                                        {"stream", "timestamp", "message": {…}, "mapping"?}; or a list
    GET    /api/streams                 per-stream counters
    POST   /api/reason                  JSON individuals or Turtle → inferred facts (Pellet + SWRL)
"""

from __future__ import annotations

import asyncio
import json
import logging
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, AsyncIterator

from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import JSONResponse, Response, StreamingResponse
from fastapi.security import HTTPAuthorizationCredentials, HTTPBearer
from starlette.concurrency import run_in_threadpool

from gateway.config import Settings, StreamSettings
from gateway.ontology.reasoner import Reasoner, ReasonerError
from gateway.rdf.mapping import Mapper, MappingError
from gateway.rdf.terms import TermError, parse_triple
from gateway.stream.engine import QueryNotFound, StreamEngine, StreamError
from gateway.stream.lexer import QueryParseError
from gateway.stream.query import ParamSpec
from gateway.stream.rules import BindingError, RuleBinding

log = logging.getLogger(__name__)

router = APIRouter(tags=["streams"])
_bearer = HTTPBearer(auto_error=False)
MAX_BATCH = 10_000
SSE_QUEUE = 1000


@dataclass
class StreamServices:
    """What the stream routes need; built once by :func:`build_services`."""

    engine: StreamEngine
    mapper: Mapper
    reasoner: Reasoner | None
    settings: StreamSettings
    pending: threading.BoundedSemaphore = field(init=False)
    rejected_posts: int = 0

    def __post_init__(self) -> None:
        self.pending = threading.BoundedSemaphore(self.settings.max_pending_posts)


_services: StreamServices | None = None


def configure(services: StreamServices | None) -> None:
    """Hand the services to the router (call at app start-up; None to detach)."""
    global _services
    _services = services


def build_services(settings: Settings, rules_engine: Any = None, warm: bool = True) -> StreamServices:
    """The standard wiring: stream engine (+ rules), mapper, Pellet reasoner, and the .rq files of
    ``settings.streams.queries_dir`` registered (a broken file is logged, not fatal).

    ``warm`` runs the reasoner once here (starting the JVM in the calling thread — call this from
    the main thread: a JVM started from a worker thread makes interpreter exit hang)."""
    cfg = settings.streams
    engine = StreamEngine(cfg, rules_engine=rules_engine)
    if cfg.queries_dir and Path(cfg.queries_dir).is_dir():
        for path in sorted(Path(cfg.queries_dir).glob("*.rq")):
            try:
                engine.register(path.read_text(encoding="utf-8"), replace=True)
            except (QueryParseError, StreamError) as exc:
                log.error("query file %s not registered: %s", path, exc)
    reasoner = Reasoner(cfg.ontology_file, cfg.swrl_file)
    if warm:
        reasoner.warm_up()
    return StreamServices(engine=engine, mapper=Mapper(), reasoner=reasoner, settings=cfg)


def _svc(request: Request) -> StreamServices:
    services = _services or getattr(request.app.state, "stream_services", None)
    if services is None:
        raise _ApiFailure(503, "stream reasoning is not configured on this gateway")
    return services


class _ApiFailure(Exception):
    def __init__(self, status: int, message: str, **extra: Any) -> None:
        super().__init__(message)
        self.status, self.message, self.extra = status, message, extra


def _role(role: str) -> Any:
    """The app's bearer-token check when the app has one (open otherwise, e.g. a bare test app)."""

    def dependency(request: Request, bearer: HTTPAuthorizationCredentials | None = Depends(_bearer)) -> Any:
        auth = getattr(request.app.state, "auth", None)
        return None if auth is None else auth.check(role, bearer)

    return Depends(dependency)


def _error(status: int, message: str, **extra: Any) -> JSONResponse:
    return JSONResponse({"error": message, **extra}, status_code=status)


def _guarded(fn: Any) -> Any:
    """Turn the domain errors of a route into JSON responses."""
    import functools

    @functools.wraps(fn)
    async def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return await fn(*args, **kwargs)
        except _ApiFailure as exc:
            return _error(exc.status, exc.message, **exc.extra)
        except QueryParseError as exc:
            return _error(422, exc.message, line=exc.line, column=exc.column)
        except QueryNotFound as exc:
            return _error(404, str(exc))
        except (BindingError, StreamError) as exc:
            status = 409 if "already registered" in str(exc) else 422
            return _error(status, str(exc))
        except (MappingError, TermError) as exc:
            return _error(422, exc.message, where=exc.where)
        except ReasonerError as exc:
            return _error(exc.status, exc.message, where=exc.where)

    return wrapper


async def _json_body(request: Request) -> Any:
    raw = await request.body()
    try:
        return json.loads(raw)
    except json.JSONDecodeError as exc:
        raise _ApiFailure(422, f"invalid JSON: {exc.msg}", line=exc.lineno, column=exc.colno) from None
    except UnicodeDecodeError:
        raise _ApiFailure(422, "the body is not UTF-8") from None


def _is_json(request: Request) -> bool:
    return "json" in request.headers.get("content-type", "application/json")


# -- queries ------------------------------------------------------------------------------------


@router.post("/api/queries", status_code=201, dependencies=[_role("author")])
@_guarded
async def register_query(request: Request) -> Any:
    """Register a C-SPARQL query (text, or JSON with params/replace/rules); 422 with line/column."""
    svc = _svc(request)
    replace, binding, params = False, None, None
    if _is_json(request):
        body = await _json_body(request)
        if not isinstance(body, dict) or not isinstance(body.get("query"), str):
            raise _ApiFailure(422, "expected {\"query\": \"REGISTER QUERY …\"}", field="query")
        text = body["query"]
        replace = bool(body.get("replace", False))
        params = _params(body.get("params"))
        if body.get("rules") is not None:
            binding = _binding(body["rules"])
    else:
        text = (await request.body()).decode("utf-8", errors="replace")
    info = await run_in_threadpool(svc.engine.register, text, params, replace, binding)
    return JSONResponse(info, status_code=201)


def _params(raw: Any) -> list[ParamSpec] | None:
    if raw is None:
        return None
    if not isinstance(raw, dict):
        raise _ApiFailure(422, "params must be {name: {\"sparql\": …} | {\"value\": …}}", field="params")
    out = []
    for name, spec in raw.items():
        if not isinstance(spec, dict) or ("sparql" in spec) == ("value" in spec):
            raise _ApiFailure(422, "give exactly one of 'sparql' or 'value'", field=f"params.{name}")
        value = spec.get("value")
        if value is not None and not isinstance(value, str):
            value = json.dumps(value)
        out.append(ParamSpec(name=name.lstrip("?$"), sparql=spec.get("sparql"), value=value))
    return out


def _binding(raw: Any) -> RuleBinding:
    if not isinstance(raw, dict) or not isinstance(raw.get("ruleset"), str) or not isinstance(raw.get("fact_type"), str):
        raise _ApiFailure(422, "rules must be {\"ruleset\": …, \"fact_type\": …, \"fields\"?, \"mode\"?}", field="rules")
    fields = raw.get("fields")
    if fields is not None and (not isinstance(fields, dict) or not all(isinstance(v, str) for v in fields.values())):
        raise _ApiFailure(422, "fields must map fact fields to query variable names", field="rules.fields")
    return RuleBinding(ruleset=raw["ruleset"], fact_type=raw["fact_type"],
                       fields={k: v.lstrip("?") for k, v in fields.items()} if fields else None,
                       mode=str(raw.get("mode", "stateless")), local_names=bool(raw.get("local_names", True)))


@router.get("/api/queries", dependencies=[_role("caller")])
@_guarded
async def list_queries(request: Request) -> Any:
    return {"queries": _svc(request).engine.queries()}


@router.get("/api/queries/{name}", dependencies=[_role("caller")])
@_guarded
async def get_query(request: Request, name: str) -> Any:
    return _svc(request).engine.query_info(name)


@router.delete("/api/queries/{name}", status_code=204, response_model=None, response_class=Response,
               dependencies=[_role("author")])
@_guarded
async def delete_query(request: Request, name: str) -> Any:
    await run_in_threadpool(_svc(request).engine.unregister, name)
    return Response(status_code=204)


@router.put("/api/queries/{name}/rules", dependencies=[_role("author")])
@_guarded
async def bind_rules(request: Request, name: str) -> Any:
    binding = _binding(await _json_body(request))
    return await run_in_threadpool(_svc(request).engine.bind_rules, name, binding)


@router.delete("/api/queries/{name}/rules", dependencies=[_role("author")])
@_guarded
async def unbind_rules(request: Request, name: str) -> Any:
    return await run_in_threadpool(_svc(request).engine.bind_rules, name, None)


@router.get("/api/queries/{name}/results", dependencies=[_role("caller")])
@_guarded
async def query_results(request: Request, name: str, limit: int = Query(20, ge=1, le=1000)) -> Any:
    return {"query": name, "results": _svc(request).engine.results(name, limit)}


@router.get("/api/queries/{name}/live", dependencies=[_role("caller")])
@_guarded
async def query_live(request: Request, name: str, max_events: int | None = Query(None, ge=1)) -> Any:
    svc = _svc(request)
    svc.engine.query_info(name)  # 404 for an unknown query
    return _sse(request, svc, name, max_events)


@router.get("/api/streams/live", dependencies=[_role("caller")])
@_guarded
async def all_live(request: Request, max_events: int | None = Query(None, ge=1)) -> Any:
    return _sse(request, _svc(request), None, max_events)


def _sse(request: Request, svc: StreamServices, query: str | None, max_events: int | None) -> StreamingResponse:
    """A live feed: each engine event as ``event: <kind>`` + JSON data; bounded queue, drops counted."""
    loop = asyncio.get_running_loop()
    queue: asyncio.Queue[dict[str, Any]] = asyncio.Queue(maxsize=SSE_QUEUE)
    dropped = [0]

    def put(event: dict[str, Any]) -> None:
        try:
            queue.put_nowait(event)
        except asyncio.QueueFull:
            dropped[0] += 1

    def on_event(event: dict[str, Any]) -> None:
        loop.call_soon_threadsafe(put, event)

    token = svc.engine.subscribe(on_event, query)

    async def events() -> AsyncIterator[bytes]:
        sent = 0
        try:
            yield b": connected\n\n"
            while max_events is None or sent < max_events:
                try:
                    event = await asyncio.wait_for(queue.get(), timeout=15)
                except asyncio.TimeoutError:
                    if await request.is_disconnected():
                        return
                    yield b": keep-alive\n\n"
                    continue
                if dropped[0]:
                    yield f"event: dropped\ndata: {json.dumps({'dropped': dropped[0]})}\n\n".encode()
                    dropped[0] = 0
                yield f"event: {event.get('kind', 'message')}\ndata: {json.dumps(event, default=str)}\n\n".encode()
                sent += 1
        finally:
            svc.engine.unsubscribe(token)

    return StreamingResponse(events(), media_type="text/event-stream",
                             headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})


# -- streams --------------------------------------------------------------------------------------


@router.post("/api/streams", dependencies=[_role("caller")])
@_guarded
async def post_stream(request: Request) -> Any:
    """One message or a list of messages; triples or a message mapped to RDF. 503 when saturated."""
    svc = _svc(request)
    body = await _json_body(request)
    messages = body if isinstance(body, list) else [body]
    if len(messages) > MAX_BATCH:
        raise _ApiFailure(413, f"at most {MAX_BATCH} messages per request")
    prepared = [_prepare(svc, m, f"[{i}]" if isinstance(body, list) else "") for i, m in enumerate(messages)]
    if not svc.pending.acquire(blocking=False):
        svc.rejected_posts += 1
        raise _ApiFailure(503, "too many stream posts in progress; retry later",
                          rejected_total=svc.rejected_posts)
    try:
        reports = await run_in_threadpool(lambda: [svc.engine.push(*m) for m in prepared])
    finally:
        svc.pending.release()
    return reports if isinstance(body, list) else reports[0]


def _prepare(svc: StreamServices, msg: Any, at: str) -> tuple[str, int, list[Any]]:
    """Validate one posted message into (stream, timestamp, triples); errors name the field."""
    if not isinstance(msg, dict):
        raise _ApiFailure(422, "expected an object with stream, timestamp and triples or message", where=at or "body")
    stream = msg.get("stream")
    if not isinstance(stream, str) or "://" not in stream and not stream.startswith("urn:"):
        raise _ApiFailure(422, "stream must be an absolute IRI", where=f"{at}.stream".lstrip("."))
    ts = msg.get("timestamp")
    if isinstance(ts, bool) or not isinstance(ts, (int, float)) or ts != ts or ts < 0 or ts > 2**53:
        raise _ApiFailure(422, "timestamp must be a non-negative number of milliseconds", where=f"{at}.timestamp".lstrip("."))
    if ("triples" in msg) == ("message" in msg):
        raise _ApiFailure(422, "give exactly one of 'triples' or 'message'", where=at or "body")
    if "triples" in msg:
        raw = msg["triples"]
        if not isinstance(raw, list):
            raise _ApiFailure(422, "triples must be a list of [s, p, o]", where=f"{at}.triples".lstrip("."))
        if len(raw) > svc.settings.max_message_triples:
            raise _ApiFailure(413, f"at most {svc.settings.max_message_triples} triples per message",
                              where=f"{at}.triples".lstrip("."))
        triples = [parse_triple(t, f"{at}.triples[{i}]".lstrip(".")) for i, t in enumerate(raw)]
    else:
        mapping = msg.get("mapping") or svc.settings.stream_mappings.get(stream)
        try:
            triples = svc.mapper.map(msg["message"], int(ts), mapping)
        except MappingError as exc:
            raise _ApiFailure(422, exc.message, where=(at + "." if at else "") + exc.where) from None
    return stream, int(ts), triples


@router.get("/api/streams", dependencies=[_role("caller")])
@_guarded
async def stream_stats(request: Request) -> Any:
    svc = _svc(request)
    return {"streams": dict(svc.engine.stream_stats), "rejected_posts": svc.rejected_posts,
            "subscriber_errors": svc.engine.subscriber_errors}


# -- reasoning ------------------------------------------------------------------------------------


@router.post("/api/reason", dependencies=[_role("caller")])
@_guarded
async def reason(request: Request) -> Any:
    """Pellet + SWRL over the ontology and the posted individuals (JSON or text/turtle)."""
    svc = _svc(request)
    if svc.reasoner is None:
        raise _ApiFailure(503, "no reasoner configured")
    if _is_json(request):
        data: Any = await _json_body(request)
    else:
        data = (await request.body()).decode("utf-8", errors="replace")
    return await run_in_threadpool(svc.reasoner.reason, data)
