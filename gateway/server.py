"""The composition root: one running gateway = engine + Information State + stream reasoning + REST.

Why one place: ``printeps serve``, ``printeps demo`` and the end-to-end tests must wire the same
parts the same way — the rules engine with the rule sets from ``rules/drl``, the Information State
recording every decision, the C-SPARQL engine bound to the rules, and the REST app exposing them.
Adapters stay thin; this module only connects them.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any, Callable

from fastapi import FastAPI

from gateway import jvm
from gateway.config import Settings

log = logging.getLogger(__name__)

RULE_FIRINGS = "rule_firings"
RULESET_EVENTS = "ruleset_events"


def information_state_recorder(store: Any, record_fires: bool = True) -> Callable[[str, dict[str, Any]], None]:
    """An engine listener that keeps every decision and every rule set change in the store.

    ``store`` should be a :class:`~gateway.store.write_behind.WriteBehind`, so that firing never
    waits for the database. Firings that the ROS pipeline records itself
    (``context.origin == "ros"``, with the sensor reading they came from) are not written twice.
    """

    def on_engine_event(kind: str, payload: dict[str, Any]) -> None:
        if kind == "fire":
            if not record_fires or (payload.get("context") or {}).get("origin") == "ros":
                return
            doc = {k: payload.get(k) for k in ("ruleset", "version", "facts", "fired", "actions", "fire_count", "duration_ms")}
            doc["context"] = payload.get("context") or {"origin": "api"}
            store.record(RULE_FIRINGS, doc, stored_type="printeps/RuleFiring", inserted_by="gateway")
        elif kind in ("deploy", "rollback", "delete"):
            store.record(RULESET_EVENTS, {"event": kind, **payload}, stored_type=f"printeps/RuleSet/{kind}",
                         inserted_by="gateway")

    return on_engine_event


@dataclass
class Gateway:
    """A wired gateway; ``close()`` stops what it started (the embedded database among them)."""

    settings: Settings
    engine: Any
    store: Any
    app: FastAPI
    stream_services: Any = None
    _owns_store: bool = field(default=True, repr=False)

    def close(self) -> None:
        writer = getattr(self.app.state, "store_writer", None)
        if writer is not None:
            writer.close()  # everything queued reaches the store before it closes
        if self._owns_store and self.store is not None:
            self.store.close()


def build_app(
    settings: Settings,
    engine: Any,
    store: Any = None,
    *,
    streams: bool = True,
    health_checks: dict[str, Any] | None = None,
) -> tuple[FastAPI, Any]:
    """The REST app around an existing engine (and store): returns ``(app, stream_services)``."""
    from gateway.api.app import create_app

    from gateway.store.write_behind import WriteBehind

    checks = dict(health_checks or {})
    writer = None
    if store is not None:
        checks.setdefault("store", store.health)
        writer = WriteBehind(store)
        engine.add_listener(information_state_recorder(writer, settings.store.record_fires))
    app = create_app(settings, engine, health_checks=checks)
    app.state.store = store
    app.state.store_writer = writer
    services = None
    if streams:
        try:
            from gateway.api.streams import build_services

            services = build_services(settings, rules_engine=engine)
            app.state.stream_services = services
        except Exception as exc:  # stream reasoning is optional: the rules keep working without it
            log.error("stream reasoning not available: %s", exc)
    return app, services


def serve_in_thread(app: FastAPI, port: int, name: str = "uvicorn", timeout_s: float = 30.0) -> tuple[Any, Any]:
    """Serve ``app`` with uvicorn on 127.0.0.1:``port`` in a daemon thread; returns once it accepts
    requests as ``(server, thread)`` (stop with ``server.should_exit = True``, then join)."""
    import threading
    import time

    import uvicorn

    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, name=name, daemon=True)
    thread.start()
    deadline = time.monotonic() + timeout_s
    while not server.started:
        if time.monotonic() > deadline or not thread.is_alive():
            server.should_exit = True
            raise RuntimeError(f"the gateway did not start on 127.0.0.1:{port} within {timeout_s:.0f} s")
        time.sleep(0.05)
    return server, thread


def build_gateway(
    settings: Settings,
    *,
    load_rules: bool = True,
    streams: bool = True,
    warm_up: bool = True,
    store: Any = None,
) -> Gateway:
    """Start the JVM (in this, the main, thread), the engine with ``rules/drl/*``, the Information
    State (``MONGO_URI`` or the embedded database) and the REST app."""
    from gateway.engine import Engine

    jvm.start(settings.jvm)
    engine = Engine(settings)
    if load_rules:
        for name, status in engine.load_rules_dir().items():
            (log.error if status.startswith("failed") else log.info)("rule set %s: %s", name, status)
    owns_store = store is None
    if store is None:
        from gateway.store import open_store

        store = open_store(settings)
    try:
        app, services = build_app(settings, engine, store, streams=streams)
    except BaseException:
        if owns_store:
            store.close()
        raise
    if warm_up:
        engine.warm_up()
    return Gateway(settings, engine, store, app, services, owns_store)
