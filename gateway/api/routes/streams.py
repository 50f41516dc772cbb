"""REST for stream reasoning: continuous queries (versioned like rule sets), stream input, results
(also live over Server-Sent Events).

The stream engine is the gateway's one stream engine: the ROS node feeds the same one, so the
windows of ROS-fed streams show here too. Queries and their rule bindings are stored in the
Information State and followed by every gateway process (:mod:`gateway.stream.services`).

    POST   /api/queries                 C-SPARQL (text/plain, or JSON {"query", "params", "replace", "rules",
                                        "report", "comment", "base_version"}); 409 when base_version is stale
    POST   /api/queries/validate        the same checks, nothing stored or served -> {"ok", "errors", …}
    GET    /api/queries                 registered queries with their counters (and current version)
    GET    /api/queries/{name}          one query (and its current version)
    DELETE /api/queries/{name}
    GET    /api/queries/{name}/versions every stored version
    GET    /api/queries/{name}/versions/{version}  its text, params, binding and report policy
    POST   /api/queries/{name}/rollback {"version"}
    PUT    /api/queries/{name}/rules    a rule binding (see gateway.stream.rules) — rows become facts
    DELETE /api/queries/{name}/rules
    GET    /api/queries/{name}/results  recent results (?limit=)
    GET    /api/queries/{name}/live     Server-Sent Events: result / actions / error events
    GET    /api/streams/live            the same for all queries
    POST   /api/streams                 {"stream", "timestamp", "triples": [[s,p,o], …]} or
                                        {"stream", "timestamp", "message": {…}, "mapping"?}; or a list
    GET    /api/streams                 per-stream counters
"""

from __future__ import annotations

import asyncio
import json
from dataclasses import dataclass
from typing import Any, AsyncIterator

from fastapi import APIRouter, Query, Request
from fastapi.responses import Response, StreamingResponse
from starlette.concurrency import run_in_threadpool

from gateway.api.deps import Author, Caller, GatewayDep, QueriesDep, StreamsDep
from gateway.api.errors import ApiError
from gateway.api.jsonio import BadBody, JSON, JsonRoute, read_json
from gateway.rdf.mapping import MappingError
from gateway.rdf.terms import parse_triple
from gateway.stream.engine import StreamError
from gateway.stream.lexer import QueryParseError
from gateway.stream.query import ParamSpec, ReportPolicy
from gateway.stream.results import report_to_sparql_json, to_sparql_json
from gateway.stream.rules import BindingError, RuleBinding
from gateway.base.versions import CatalogConflict

router = APIRouter(tags=["streams"], route_class=JsonRoute)
MAX_BATCH = 10_000
SSE_QUEUE = 1000
SPARQL_JSON = "application/sparql-results+json"


def _is_json(request: Request) -> bool:
    return "json" in request.headers.get("content-type", "application/json")


def _params(raw: Any) -> list[ParamSpec] | None:
    if raw is None:
        return None
    if not isinstance(raw, dict):
        raise ApiError(422, "params must be {name: {\"sparql\": …} | {\"value\": …}}", field="params")
    out = []
    for name, spec in raw.items():
        if not isinstance(spec, dict) or ("sparql" in spec) == ("value" in spec):
            raise ApiError(422, "give exactly one of 'sparql' or 'value'", field=f"params.{name}")
        value = spec.get("value")
        if value is not None and not isinstance(value, str):
            value = json.dumps(value)
        out.append(ParamSpec(name=name.lstrip("?$"), sparql=spec.get("sparql"), value=value))
    return out


# -- queries ------------------------------------------------------------------------------------


@dataclass
class Registration:
    """What a registration (or a validation) asks for, read from the request body."""

    text: str
    params: list[ParamSpec] | None = None
    replace: bool = False
    rules: Any = None
    report: str | None = None
    comment: str = ""
    base_version: int | None = None

    def binding(self) -> RuleBinding | None:
        return None if self.rules is None else RuleBinding.from_dict(self.rules)

    def check_report(self) -> None:
        """A bad report policy is named as such (its line/column are in the policy, not the query)."""
        if self.report is None:
            return
        try:
            ReportPolicy.parse(self.report)
        except QueryParseError as exc:
            raise ApiError(422, f"report: {exc.message}", field="report", line=exc.line, column=exc.column) from None


#: Content types (and any text/*) a query registration takes as its C-SPARQL text (else JSON; anything else: 415).
QUERY_TEXT_TYPES = ("text/plain", "application/sparql-query")


async def _registration(request: Request) -> Registration:
    if not _is_json(request):
        content_type = request.headers.get("content-type", "").split(";", 1)[0].strip().lower()
        if content_type not in QUERY_TEXT_TYPES and not content_type.startswith("text/"):
            raise BadBody(f"content type {content_type!r} is not supported; send the query as text/plain or "
                          "JSON (application/json)", status=415)
        return Registration((await request.body()).decode("utf-8", errors="replace"))
    body = await read_json(request)
    if not isinstance(body, dict) or not isinstance(body.get("query"), str):
        raise ApiError(422, "expected {\"query\": \"REGISTER QUERY …\"}", field="query")
    report = body.get("report")
    if report is not None and not isinstance(report, str):
        raise ApiError(422, "report must be a policy such as \"content change\"", field="report")
    comment = body.get("comment", "")
    if not isinstance(comment, str) or len(comment) > 2000:
        raise ApiError(422, "comment must be a text of at most 2000 characters", field="comment")
    base = body.get("base_version")
    if base is not None and (isinstance(base, bool) or not isinstance(base, int) or base < 0):
        raise ApiError(422, "base_version must be a version number (0: a new query)", field="base_version")
    return Registration(body["query"], _params(body.get("params")), bool(body.get("replace", False)),
                        body.get("rules"), report, comment, base)


@router.post("/api/queries", status_code=201)
async def register_query(request: Request, queries: QueriesDep, who: Author) -> JSON:
    """Register a C-SPARQL query (text, or JSON with params/replace/rules/report/comment/base_version);
    422 with line/column; 409 when the name is taken or ``base_version`` is not current any more."""
    reg = await _registration(request)
    reg.check_report()
    binding = reg.binding()
    try:
        info = await run_in_threadpool(lambda: queries.register(
            reg.text, reg.params, reg.replace, binding, report=reg.report, author=who.name, comment=reg.comment,
            base_version=reg.base_version))
    except CatalogConflict as exc:
        raise ApiError(409, "base version changed: someone saved this query meanwhile", current=exc.current) from None
    return JSON(info, status_code=201)


@router.post("/api/queries/validate")
async def validate_query(request: Request, queries: QueriesDep, _: Caller) -> JSON:
    """Every check of a registration, nothing stored or served: ``{"ok": true, "name", "exists",
    "version", "query": info}`` or ``{"ok": false, "errors": [{"field", "message", "line"?, "column"?}]}``."""
    reg = await _registration(request)
    try:
        reg.check_report()
        binding = reg.binding()
        checked = await run_in_threadpool(lambda: queries.validate(reg.text, reg.params, binding, reg.report))
    except ApiError as exc:
        return JSON({"ok": False, "errors": [{"message": exc.message, **exc.extra}]})
    except QueryParseError as exc:
        return JSON({"ok": False, "errors": [{"field": "query", **exc.to_dict()}]})
    except BindingError as exc:
        return JSON({"ok": False, "errors": [{"field": "rules", "message": str(exc)}]})
    except StreamError as exc:
        return JSON({"ok": False, "errors": [{"field": "query", "message": str(exc)}]})
    return JSON({"ok": True, "errors": [], **checked})


@router.get("/api/queries")
async def list_queries(streams: StreamsDep, queries: QueriesDep, _: Caller) -> JSON:
    return JSON({"queries": [{**q, "version": queries.current_version(q["name"])} for q in streams.queries()]})


@router.get("/api/queries/{name}")
async def get_query(name: str, streams: StreamsDep, queries: QueriesDep, _: Caller) -> JSON:
    return JSON({**streams.query_info(name), "version": queries.current_version(name)})


@router.delete("/api/queries/{name}", status_code=204, response_model=None, response_class=Response)
async def delete_query(name: str, queries: QueriesDep, who: Author) -> Response:
    await run_in_threadpool(lambda: queries.unregister(name, author=who.name))
    return Response(status_code=204)


@router.get("/api/queries/{name}/versions")
async def query_versions(name: str, queries: QueriesDep, _: Caller) -> JSON:
    return JSON([i.to_dict() for i in await run_in_threadpool(queries.versions, name)])


@router.get("/api/queries/{name}/versions/{version}")
async def query_version(name: str, version: int, queries: QueriesDep, _: Caller) -> JSON:
    return JSON(await run_in_threadpool(lambda: queries.version(name, version)))


@router.post("/api/queries/{name}/rollback")
async def rollback_query(name: str, request: Request, queries: QueriesDep, who: Author) -> JSON:
    body = await read_json(request)
    if not isinstance(body, dict) or not isinstance(body.get("version"), int) or body["version"] < 1:
        raise ApiError(422, "expected {\"version\": n}", field="version")
    return JSON(await run_in_threadpool(lambda: queries.rollback(name, body["version"], author=who.name)))


@router.put("/api/queries/{name}/rules")
async def bind_rules(name: str, request: Request, queries: QueriesDep, who: Author) -> JSON:
    binding = RuleBinding.from_dict(await read_json(request))
    return JSON(await run_in_threadpool(lambda: queries.bind_rules(name, binding, author=who.name)))


@router.delete("/api/queries/{name}/rules")
async def unbind_rules(name: str, queries: QueriesDep, who: Author) -> JSON:
    return JSON(await run_in_threadpool(lambda: queries.bind_rules(name, None, author=who.name)))


def wants_sparql_json(request: Request) -> bool:
    return SPARQL_JSON in request.headers.get("accept", "")


@router.get("/api/queries/{name}/results")
async def query_results(request: Request, name: str, streams: StreamsDep, _: Caller,
                        limit: int = Query(20, ge=1, le=1000), nonempty: bool = False) -> JSON:
    """Every reported window (empty ones too, unless ``nonempty``), oldest first; with ``Accept:
    application/sparql-results+json`` the bindings are RDF terms (SPARQL 1.1 Query Results JSON)."""
    results = streams.results(name, limit, nonempty)
    if wants_sparql_json(request):
        return JSON({"query": name, "results": [to_sparql_json(e) for e in results]}, media_type=SPARQL_JSON)
    return JSON({"query": name, "results": results})


@router.get("/api/queries/{name}/live")
async def query_live(request: Request, name: str, streams: StreamsDep, _: Caller,
                     max_events: int | None = Query(None, ge=1), nonempty: bool = False,
                     format: str = Query("json", pattern="^(json|sparql-json)$")) -> StreamingResponse:
    streams.query_info(name)  # 404 for an unknown query
    return _sse(request, streams, name, max_events, nonempty, format == "sparql-json")


@router.get("/api/streams/live")
async def all_live(request: Request, streams: StreamsDep, _: Caller, max_events: int | None = Query(None, ge=1),
                   nonempty: bool = False,
                   format: str = Query("json", pattern="^(json|sparql-json)$")) -> StreamingResponse:
    return _sse(request, streams, None, max_events, nonempty, format == "sparql-json")


def _sse(request: Request, streams: Any, query: str | None, max_events: int | None, nonempty: bool = False,
         sparql_json: bool = False) -> StreamingResponse:
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

    token = streams.subscribe(on_event, query, nonempty=nonempty)

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
                if sparql_json:
                    event = to_sparql_json(event)
                yield f"event: {event.get('kind', 'message')}\ndata: {json.dumps(event, default=str)}\n\n".encode()
                sent += 1
        finally:
            streams.unsubscribe(token)

    return StreamingResponse(events(), media_type="text/event-stream",
                             headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})


# -- streams --------------------------------------------------------------------------------------


@router.post("/api/streams")
async def post_stream(request: Request, gateway: GatewayDep, _: Caller) -> JSON:
    """One message or a list of messages; triples or a message mapped to RDF. 503 when saturated."""
    body = await read_json(request)
    messages = body if isinstance(body, list) else [body]
    if len(messages) > MAX_BATCH:
        raise ApiError(413, f"at most {MAX_BATCH} messages per request")
    prepared = [_prepare(gateway, m, f"[{i}]" if isinstance(body, list) else "") for i, m in enumerate(messages)]
    pending = request.app.state.stream_posts
    if not pending.acquire(blocking=False):
        request.app.state.rejected_stream_posts += 1
        raise ApiError(503, "too many stream posts in progress; retry later",
                       rejected_total=request.app.state.rejected_stream_posts)
    sparql = wants_sparql_json(request) or request.query_params.get("results") == "true"
    try:
        reports = await run_in_threadpool(lambda: [gateway.streams.push(*m, with_results=sparql) for m in prepared])
    finally:
        pending.release()
    if sparql:
        reports = [report_to_sparql_json(r) for r in reports]
    return JSON(reports if isinstance(body, list) else reports[0])


def _prepare(gateway: Any, msg: Any, at: str) -> tuple[str, int, list[Any]]:
    """Validate one posted message into (stream, timestamp, triples); errors name the field."""
    settings = gateway.settings.streams
    if not isinstance(msg, dict):
        raise ApiError(422, "expected an object with stream, timestamp and triples or message", where=at or "body")
    stream = msg.get("stream")
    if not isinstance(stream, str) or "://" not in stream and not stream.startswith("urn:"):
        raise ApiError(422, "stream must be an absolute IRI", where=f"{at}.stream".lstrip("."))
    ts = msg.get("timestamp")
    if isinstance(ts, bool) or not isinstance(ts, (int, float)) or ts != ts or ts < 0 or ts > 2**53:
        raise ApiError(422, "timestamp must be a non-negative number of milliseconds", where=f"{at}.timestamp".lstrip("."))
    if ("triples" in msg) == ("message" in msg):
        raise ApiError(422, "give exactly one of 'triples' or 'message'", where=at or "body")
    if "triples" in msg:
        raw = msg["triples"]
        if not isinstance(raw, list):
            raise ApiError(422, "triples must be a list of [s, p, o]", where=f"{at}.triples".lstrip("."))
        if len(raw) > settings.max_message_triples:
            raise ApiError(413, f"at most {settings.max_message_triples} triples per message",
                           where=f"{at}.triples".lstrip("."))
        triples = [parse_triple(t, f"{at}.triples[{i}]".lstrip(".")) for i, t in enumerate(raw)]
    else:
        mapping = msg.get("mapping") or settings.stream_mappings.get(stream)
        try:
            triples = gateway.mapper.map(msg["message"], int(ts), mapping)
        except MappingError as exc:
            raise ApiError(422, exc.message, where=(at + "." if at else "") + exc.where) from None
    return stream, int(ts), triples


@router.get("/api/streams")
async def stream_stats(request: Request, streams: StreamsDep, _: Caller) -> JSON:
    return JSON({"streams": dict(streams.stream_stats), "rejected_posts": request.app.state.rejected_stream_posts,
                 "subscriber_errors": streams.subscriber_errors})
