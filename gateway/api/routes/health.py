"""``GET /health``: is this gateway process serving, and what do its parts say.

The engine decides: 200 while it serves (the store, ROS or the follower may be degraded — the body
says so), 503 when it cannot. A part whose check raises is reported as down, never as a 500.
"""

from __future__ import annotations

from fastapi import APIRouter

from gateway.api.deps import GatewayDep
from gateway.api.jsonio import JSON, JsonRoute

router = APIRouter(tags=["operations"], route_class=JsonRoute)


@router.get("/health")
def health(gateway: GatewayDep) -> JSON:
    """``{"status": "ok" | "degraded" | "down", "engine": …, "store": …, "ros": …, "sync": …}``."""
    try:
        report = gateway.health()
    except Exception as exc:  # a broken part is reported, not propagated
        report = {"engine": {"status": "down", "error": f"{type(exc).__name__}: {exc}"}}
    engine_ok = report.get("engine", {}).get("status") == "ok"
    others_ok = all(v.get("status") in ("ok", "not configured") for v in report.values())
    status = "ok" if engine_ok and others_ok else ("degraded" if engine_ok else "down")
    return JSON({"status": status, "process": gateway.name, **report}, status_code=200 if engine_ok else 503)
