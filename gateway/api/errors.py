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
from gateway.engine import (
    CompileFailed,
    CompileResourceError,
    EngineError,
    FactError,
    InvalidRuleSet,
    RuleRuntimeError,
    RuleSetNotFound,
    RunawayRules,
    VersionConflict,
    VersionNotFound,
)

log = logging.getLogger(__name__)


class ApiError(Exception):
    """An error the API raises itself: ``status`` + message + extra JSON fields."""

    def __init__(self, status: int, message: str, headers: dict[str, str] | None = None, **extra: Any) -> None:
        super().__init__(message)
        self.status = status
        self.message = message
        self.headers = headers
        self.extra = extra


def error_body(message: str, **extra: Any) -> dict[str, Any]:
    return {"error": message, **extra}


def engine_error_response(exc: EngineError) -> tuple[int, dict[str, Any]]:
    """(status, body) for an engine error. Bodies are the engine's own ``to_dict()``
    (``{"error", "kind", ...}``: compile errors with file/line/column, bad facts with index/field)."""
    body = exc.to_dict()
    body.setdefault("error", str(exc) or type(exc).__name__)
    if isinstance(exc, VersionConflict):
        body["error"] = "base version changed"
        return 409, body
    if isinstance(exc, (RuleSetNotFound, VersionNotFound)):
        return 404, body
    if isinstance(exc, CompileResourceError):  # a server limit (memory, time), not the author's text
        return 503, body
    if isinstance(exc, (CompileFailed, InvalidRuleSet, FactError, RunawayRules, RuleRuntimeError)):
        return 422, body
    return 500, body


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
        return JSON(error_body(exc.message, **exc.extra), status_code=exc.status, headers=exc.headers)

    @app.exception_handler(BadBody)
    async def _bad_body(request: Request, exc: BadBody) -> JSON:
        count("bad_body")
        return JSON(error_body(exc.message, **exc.extra), status_code=exc.status)

    @app.exception_handler(EngineError)
    async def _engine_error(request: Request, exc: EngineError) -> JSON:
        status, body = engine_error_response(exc)
        count(type(exc).__name__)
        if status >= 500:
            log.error("engine error on %s %s: %s", request.method, request.url.path, exc)
        return JSON(body, status_code=status)

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSON:
        count("invalid_request")
        return JSON(error_body("invalid request", errors=_validation_errors(exc)), status_code=422)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSON:
        count(f"http_{exc.status_code}")
        message = exc.detail if isinstance(exc.detail, str) else "request failed"
        body = error_body(message) if isinstance(exc.detail, str) else error_body(message, detail=exc.detail)
        return JSON(body, status_code=exc.status_code, headers=getattr(exc, "headers", None))

    @app.exception_handler(Exception)
    async def _internal(request: Request, exc: Exception) -> JSON:
        count("internal")
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        return JSON(error_body("internal error", type=type(exc).__name__, message=str(exc)), status_code=500)
