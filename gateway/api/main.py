"""``create_app(gateway)``: the REST application of one built gateway.

Why it builds nothing: the services (engine, knowledge, streams, workflows, the Information State)
come from :func:`gateway.app.build_gateway`; this only puts the explicit list of routers, the
error handlers, the body limit and the metrics around them. Routes get what they need through
:mod:`gateway.api.deps`.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from fastapi import FastAPI
from fastapi.responses import RedirectResponse

from gateway.api.auth import Authenticator
from gateway.api.errors import install_error_handlers
from gateway.api.limits import BodyLimit
from gateway.api.metrics import Metrics
from gateway.config import ApiSettings
from gateway.engine.bulkhead import Bulkheads
from gateway.api.routes import (
    authoring, decisions, dialogue, explain, health, jobs, kie_server, knowledge, knowledge_editor, live, mappings, metrics, outline, replay, stream_replay,
    rulesets, sessions, state, streams, workflows,
)
from gateway.workbench import router as workbench

log = logging.getLogger(__name__)

ROUTERS = (
    rulesets.router, jobs.router, sessions.router, authoring.router, outline.router, decisions.router, kie_server.router, streams.router, mappings.router, knowledge_editor.router, knowledge.router,
    dialogue.router, workflows.router, state.router, health.router, metrics.router, live.router, replay.router, stream_replay.router, explain.router,
    workbench.router,
)

DESCRIPTION = """Manage and fire PRINTEPS business rule sets (Drools), continuous queries, workflows and
the teahouse knowledge over HTTP.

Auth: `Authorization: Bearer <token>` (roles `author`, `caller`); KIE Server endpoints also accept
HTTP basic auth. With no tokens configured the API runs open (dev mode). Errors are JSON:
`{"error": "...", ...}`."""


#: FastAPI's native telemetry, each signal off (see create_app).
NO_TELEMETRY: dict[str, bool] = {"tracing": False, "metrics": False, "logs": False}

def create_app(gateway: Any, api: ApiSettings | None = None) -> FastAPI:
    """The app over ``gateway`` (a :class:`gateway.app.Gateway`); ``api`` overrides the gateway's
    API settings (auth, limits) for this app only."""
    settings = gateway.settings if api is None else gateway.settings.model_copy(update={"api": api})
    # FastAPI's native OpenTelemetry off: the gateway configures no provider, and asking whether one
    # is configured cost every request ~5-15 us on the event loop (its /metrics are Prometheus)
    app = FastAPI(title="PRINTEPS gateway", version="0.1.0", description=DESCRIPTION, telemetry=NO_TELEMETRY)
    app.state.gateway = gateway
    app.state.settings = settings
    app.state.engine = gateway.engine  # the fire route reads it directly: no dependency on the hot path
    app.state.auth = Authenticator(settings.api)
    app.state.metrics = Metrics()
    # each rule set's fire threads and queue (gateway.engine.bulkhead): no fire runs on the event loop
    app.state.bulkheads = Bulkheads(settings.api.fire_workers, settings.api.max_queue, settings.api.max_wait_s)
    app.state.metrics.watch_bulkheads(app.state.bulkheads.stats, settings.api.max_queue)
    app.state.stream_posts = threading.BoundedSemaphore(settings.streams.max_pending_posts)
    app.state.rejected_stream_posts = 0
    gateway.engine.add_listener(app.state.metrics.on_engine_event, fires=False)  # it counts deploys, not decisions
    install_error_handlers(app)
    # the hot routes first, so they are matched before any other (see gateway.api.lean_route)
    app.router.routes[0:0] = [rulesets.FIRE_ROUTE, kie_server.BATCH_ROUTE]
    for router in ROUTERS:
        app.include_router(router)

    @app.get("/", include_in_schema=False)
    def root() -> RedirectResponse:
        return RedirectResponse("/workbench", status_code=307)

    @app.get("/workflows", include_in_schema=False)
    def workflows_page() -> RedirectResponse:
        return RedirectResponse("/workbench/workflows", status_code=307)

    app.add_middleware(BodyLimit, max_bytes=settings.api.max_body_bytes)
    if settings.api.is_open:
        log.warning("REST API is open (no tokens configured): every caller acts as developer 'anonymous' and may "
                    "deploy and run any rule code")
    return app
