"""Recent decisions (fires, deploys) in a ring buffer: ``GET /api/decisions``.

Why in memory: the workbench shows "what did the rules just decide and why" without a database.
The engine's listener feeds it, so fires from ROS or workflows show up too. The Information State
(MongoDB) can replace this later by serving the same shape.
"""

from __future__ import annotations

import threading
from collections import deque
from datetime import datetime, timezone
from typing import Any

from fastapi import APIRouter, Depends, Query, Request

from gateway.api.auth import Principal, caller
from gateway.api.jsonio import JSON


class DecisionLog:
    """A bounded, thread-safe log of engine events, newest last."""

    def __init__(self, size: int) -> None:
        self._items: deque[dict[str, Any]] = deque(maxlen=max(1, size))
        self._lock = threading.Lock()
        self._seq = 0

    def on_engine_event(self, kind: str, payload: dict[str, Any]) -> None:
        """Engine listener: keep a compact record of the event."""
        entry = summarize(kind, payload)
        with self._lock:
            self._seq += 1
            entry["seq"] = self._seq
            self._items.append(entry)

    def recent(self, limit: int, ruleset: str | None = None, kind: str | None = None) -> list[dict[str, Any]]:
        """Newest first, at most ``limit``."""
        with self._lock:
            items = list(self._items)
        out = []
        for entry in reversed(items):
            if ruleset and entry.get("ruleset") != ruleset:
                continue
            if kind and entry.get("kind") != kind:
                continue
            out.append(entry)
            if len(out) >= limit:
                break
        return out


def summarize(kind: str, payload: dict[str, Any]) -> dict[str, Any]:
    """The fields the workbench shows, taken defensively from an engine event payload."""
    fired = payload.get("fired") or []
    return {
        "kind": kind,
        "time": payload.get("time") or datetime.now(timezone.utc).isoformat(timespec="milliseconds"),
        "ruleset": payload.get("ruleset") or payload.get("name"),
        "version": payload.get("version"),
        "fired": [f.get("rule") if isinstance(f, dict) else str(f) for f in fired],
        "actions": list(payload.get("actions") or []),
        "facts_in": len(facts) if isinstance(facts := payload.get("facts"), list) else None,
        "fire_count": payload.get("fire_count"),
        "duration_ms": payload.get("duration_ms"),
        "author": payload.get("by") or payload.get("author"),
    }


router = APIRouter(tags=["rule sets"])


@router.get("/api/decisions")
def decisions(
    request: Request,
    limit: int = Query(50, ge=1, le=10_000),
    ruleset: str | None = Query(None, max_length=200),
    kind: str | None = Query(None, max_length=40),
    _: Principal = Depends(caller),
) -> JSON:
    """Recent fires/deploys, newest first: kind, time, ruleset, version, fired rules, actions."""
    return JSON(request.app.state.decisions.recent(limit, ruleset, kind))
