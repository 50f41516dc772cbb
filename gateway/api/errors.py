"""Every failure becomes a JSON body with a clear message and a fitting 4xx/5xx status.

Why one module: the engine raises domain errors (compile errors with file/line/column, bad facts
with index/field, version conflicts); the HTTP edge maps each to exactly one status so clients (the
workbench, the CLI, robots) can rely on ``{"error": "...", ...}`` everywhere, including for request
validation, unknown routes and internal faults.
"""

from __future__ import annotations

import logging
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from starlette.exceptions import HTTPException as StarletteHTTPException

from gateway.api.jsonio import JSON, BadBody
from gateway.runtime.jobs import JobError
from gateway.ontology.editor import NotFound as KnowledgeItemNotFound
from gateway.rdf.mapping import MappingError
from gateway.rdf.terms import TermError
from gateway.store.store import StoreUnavailable
from gateway.stream.engine import QueryNotFound, StreamError
from gateway.stream.lexer import QueryParseError
from gateway.stream.rules import BindingError
from gateway.base.versions import CatalogUnavailable
from gateway.engine import EngineError, VersionConflict
from gateway.engine.errors import FireTimeout, Overloaded
from gateway.engine.durable import RebuildFailed
from gateway.engine.session import CommandFailed
from gateway.engine.sessions import SessionNotFound, SessionRefused

log = logging.getLogger(__name__)


class ApiError(Exception):
    """An error the API raises itself: ``status`` + message + extra JSON fields."""

    def __init__(self, status: int, message: str, headers: dict[str, str] | None = None, **extra: Any) -> None:
        super().__init__(message)
        self.status = status
        self.message = message
        self.headers = headers
        self.extra = extra


#: The ``kind`` of an error body that names none itself, by status: every error body of the API is
#: ``{"error", "kind", ...}`` (docs/rest-api.md, "Errors"), so clients can branch on ``kind``.
KIND_BY_STATUS = {400: "body", 401: "auth", 403: "forbidden", 404: "not_found", 405: "method", 409: "conflict",
                  410: "gone", 413: "too_large", 415: "media_type", 421: "misdirected", 422: "request",
                  429: "limit", 500: "internal", 503: "unavailable"}


def kind_for(status: int) -> str:
    """The default ``kind`` of an error body with this status."""
    return KIND_BY_STATUS.get(status, "internal" if status >= 500 else "request")


def error_body(message: str, status: int = 400, **extra: Any) -> dict[str, Any]:
    """``{"error": message, "kind": …, **extra}``; ``kind`` from ``extra`` or else by ``status``."""
    return {"error": message, "kind": extra.pop("kind", None) or kind_for(status), **extra}


def engine_error_response(exc: EngineError) -> tuple[int, dict[str, Any]]:
    """(status, body) for an engine error. Bodies are the engine's own ``to_dict()``
    (``{"error", "kind", ...}``: compile errors with file/line/column, bad facts with index/field)."""
    body = exc.to_dict()
    body.setdefault("error", str(exc) or type(exc).__name__)
    if isinstance(exc, VersionConflict):
        body["error"] = "base version changed"
    return _status_of(exc), body


#: The status of an engine error by its ``kind`` — one table for errors raised here and for those
#: that travel as records (a build job's): 503 "resources" is a server limit, not the author's text.
KIND_STATUS = {"conflict": 409, "not_found": 404, "resources": 503, "compile": 422, "policy": 422, "invalid": 422,
               "facts": 422,
               "runaway": 422, "runtime": 422, "scenarios": 422, "cancelled": 409, "lost": 503, "limit": 429,
               "gone": 410, "timeout": 503, "overloaded": 503, "rebuilding": 503, "journal": 503, "rebuild": 409}


def engine_error_status(kind: str) -> int:
    """The HTTP status the synchronous call answers for an engine error of ``kind``."""
    return KIND_STATUS.get(kind, 500)


def _status_of(exc: EngineError) -> int:
    """Session errors whose status depends on more than their kind; every other by KIND_STATUS."""
    if isinstance(exc, SessionNotFound):
        return 404
    if isinstance(exc, SessionRefused):
        return 409 if exc.conflict else 422
    if isinstance(exc, Overloaded):
        return exc.status  # 429 queue full, 503 would wait too long
    if isinstance(exc, CommandFailed):
        return command_failed_status(exc)
    if isinstance(exc, RebuildFailed):
        return exc.status
    return engine_error_status(getattr(exc, "kind", ""))


def command_failed_status(exc: CommandFailed) -> int:
    """A failed command batch: 429 at a limit, 503 halted by the fire time limit, else 422."""
    return 429 if exc.kind == "limit" else 503 if exc.kind == "timeout" else 422


def retry_after(exc: Exception) -> dict[str, str] | None:
    """The ``Retry-After`` header of an overload refusal (None for other errors)."""
    seconds = getattr(exc, "retry_after_s", None)
    return None if seconds is None else {"Retry-After": str(seconds)}


def _validation_errors(exc: RequestValidationError) -> list[dict[str, Any]]:
    out = []
    for err in exc.errors():
        loc = [str(p) for p in err.get("loc", ())]
        out.append({"field": ".".join(loc), "message": err.get("msg", "invalid value")})
    return out


def install_error_handlers(app: FastAPI) -> None:
    """Register the JSON error handlers on ``app`` and count errors in its metrics."""

    def count(kind: str) -> None:
        metrics = getattr(app.state, "metrics", None)
        if metrics is not None:
            metrics.errors.labels(kind).inc()

    @app.exception_handler(ApiError)
    async def _api_error(request: Request, exc: ApiError) -> JSON:
        count(f"http_{exc.status}")
        return JSON(error_body(exc.message, exc.status, **exc.extra), status_code=exc.status, headers=exc.headers)

    @app.exception_handler(BadBody)
    async def _bad_body(request: Request, exc: BadBody) -> JSON:
        count("bad_body")
        return JSON(error_body(exc.message, exc.status, **exc.extra), status_code=exc.status)

    @app.exception_handler(EngineError)
    async def _engine_error(request: Request, exc: EngineError) -> JSON:
        status, body = engine_error_response(exc)
        body.setdefault("kind", kind_for(status))
        count(type(exc).__name__)
        if status >= 500 and not isinstance(exc, (Overloaded, FireTimeout)):  # those two are counted, not logged
            log.error("engine error on %s %s: %s", request.method, request.url.path, exc)
        return JSON(body, status_code=status, headers=retry_after(exc))

    @app.exception_handler(JobError)  # a build job refused: unknown, not cancellable, queue full
    async def _job_error(request: Request, exc: JobError) -> JSON:
        count(f"http_{exc.status}")
        return JSON(error_body(exc.message, exc.status, kind=getattr(exc, "kind", None)), status_code=exc.status)

    @app.exception_handler(QueryParseError)
    async def _query_parse(request: Request, exc: QueryParseError) -> JSON:
        count("query_parse")
        return JSON(error_body(exc.message, 422, kind="query", line=exc.line, column=exc.column), status_code=422)

    @app.exception_handler(QueryNotFound)
    @app.exception_handler(KnowledgeItemNotFound)  # no such individual, property or SWRL rule
    async def _not_found(request: Request, exc: Exception) -> JSON:
        count("http_404")
        return JSON(error_body(str(exc), 404), status_code=404)

    @app.exception_handler(StreamError)
    @app.exception_handler(BindingError)
    async def _stream_error(request: Request, exc: Exception) -> JSON:
        status = 409 if "already registered" in str(exc) else 422
        count(f"http_{status}")
        return JSON(error_body(str(exc), status, kind="conflict" if status == 409 else "stream"), status_code=status)

    @app.exception_handler(MappingError)
    @app.exception_handler(TermError)
    async def _mapping_error(request: Request, exc: Any) -> JSON:
        count("http_422")
        return JSON(error_body(exc.message, 422, kind="mapping", where=exc.where), status_code=422)

    @app.exception_handler(CatalogUnavailable)
    @app.exception_handler(StoreUnavailable)
    async def _store_down(request: Request, exc: Exception) -> JSON:
        count("store_unavailable")
        log.error("%s %s: %s", request.method, request.url.path, exc)
        return JSON(error_body(f"{exc} (changes need the Information State; firing keeps working)", 503, kind="store"),
                    status_code=503)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSON:
        count("invalid_request")
        return JSON(error_body("invalid request", 422, errors=_validation_errors(exc)), status_code=422)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSON:
        count(f"http_{exc.status_code}")
        message = exc.detail if isinstance(exc.detail, str) else "request failed"
        body = (error_body(message, exc.status_code) if isinstance(exc.detail, str)
                else error_body(message, exc.status_code, detail=exc.detail))
        return JSON(body, status_code=exc.status_code, headers=getattr(exc, "headers", None))

    @app.exception_handler(Exception)
    async def _internal(request: Request, exc: Exception) -> JSON:
        count("internal")
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        return JSON(error_body("internal error", 500, type=type(exc).__name__, detail=str(exc)), status_code=500)
