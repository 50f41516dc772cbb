"""``create_app``: the FastAPI application of the gateway (REST API, KIE Server compatibility,
health, metrics, and the routers of other modules when they are installed).

Why a factory: tests, the CLI's ``serve`` and embedders (the demo) each build an app around an
engine they own; nothing is global. Routers of other modules (streams, state, workflows,
workbench) are included when importable, so the API works without them.
"""

from __future__ import annotations

import importlib
import logging
from typing import Any

from fastapi import FastAPI

from gateway import jvm
from gateway.api import decisions, health, kie_server, metrics, rulesets
from gateway.api.auth import Authenticator
from gateway.api.errors import install_error_handlers
from gateway.api.limits import BodyLimit
from gateway.config import Settings, load_settings

log = logging.getLogger(__name__)

# Routers owned by other modules: (module, attribute). Missing modules are skipped.
OPTIONAL_ROUTERS = (
    ("gateway.api.streams", "router"),
    ("gateway.api.knowledge", "router"),
    ("gateway.api.state", "router"),
    ("gateway.api.workflows", "router"),
    ("gateway.workbench.router", "router"),
    ("gateway.api.authoring", "router"),  # issue 16: rule test scenarios, decision-table grids
)

DESCRIPTION = """Manage and fire PRINTEPS business rule sets (Drools) over HTTP.

Auth: `Authorization: Bearer <token>` (roles `author`, `caller`); KIE Server endpoints also accept
HTTP basic auth. With no tokens configured the API runs open (dev mode). Errors are JSON:
`{"error": "...", ...}`."""


def create_app(
    settings: Settings | None = None,
    engine: Any = None,
    *,
    health_checks: dict[str, health.HealthCheck] | None = None,
    include_optional: bool = True,
) -> FastAPI:
    """Build the app. ``engine`` defaults to a new ``gateway.engine.Engine(settings)``.

    ``health_checks`` adds ``/health`` sections (e.g. ``{"store": fn, "ros": fn}``); adapters may
    also add to ``app.state.health_checks`` later.
    """
    settings = settings or load_settings()
    # Start the JVM here, in the thread that builds the app (normally the main thread): a JVM first
    # started from a request's worker thread makes the interpreter hang at exit (JPype shutdown).
    jvm.start(settings.jvm)
    if engine is None:
        from gateway.engine import Engine

        engine = Engine(settings)
    app = FastAPI(title="PRINTEPS gateway", version="0.1.0", description=DESCRIPTION)
    app.state.settings = settings
    app.state.engine = engine
    app.state.auth = Authenticator(settings.api)
    app.state.metrics = metrics.Metrics()
    app.state.decisions = decisions.DecisionLog(settings.api.decisions_kept)
    app.state.health_checks = {"engine": health.engine_check(engine), **(health_checks or {})}
    engine.add_listener(app.state.metrics.on_engine_event)
    engine.add_listener(app.state.decisions.on_engine_event)

    install_error_handlers(app)
    for router in (rulesets.router, decisions.router, kie_server.router, health.router, metrics.router):
        app.include_router(router)
    if include_optional:
        for module_name, attr in OPTIONAL_ROUTERS:
            _include_optional(app, module_name, attr)
    app.add_middleware(BodyLimit, max_bytes=settings.api.max_body_bytes)
    if settings.api.is_open:
        log.warning("REST API is open (no tokens configured): every caller acts as author 'anonymous'")
    return app


def _include_optional(app: FastAPI, module_name: str, attr: str) -> None:
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name and module_name.startswith(exc.name):
            return  # the module is simply not there (yet)
        log.error("router %s could not be imported: %s", module_name, exc)
        return
    except Exception as exc:  # a broken optional module must not take the API down
        log.error("router %s could not be imported: %s", module_name, exc)
        return
    router = getattr(module, attr, None)
    if router is not None:
        app.include_router(router)
