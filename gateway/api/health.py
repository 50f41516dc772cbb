"""``GET /health``: is the engine up, and what do the store and ROS adapters say.

Why pluggable checks: the store (MongoDB) and ROS adapters are other modules; they register a
callable in ``app.state.health_checks[name]`` returning ``{"status": "ok"|"down"|..., ...}``. A
check that raises is reported as down, never as a 500.
"""

from __future__ import annotations

from typing import Any, Callable

from fastapi import APIRouter, Request

from gateway.api.jsonio import JSON

HealthCheck = Callable[[], dict[str, Any]]

router = APIRouter(tags=["operations"])


def engine_check(engine: Any) -> HealthCheck:
    def check() -> dict[str, Any]:
        import jpype

        rulesets = engine.list_rulesets()
        return {
            "status": "ok",
            "jvm": "started" if jpype.isJVMStarted() else "not started",
            "rulesets": {i.name: i.version for i in rulesets},
        }

    return check


def run_checks(checks: dict[str, HealthCheck]) -> dict[str, Any]:
    report: dict[str, Any] = {}
    for name, check in checks.items():
        try:
            report[name] = check()
        except Exception as exc:  # a broken adapter is reported, not propagated
            report[name] = {"status": "down", "error": f"{type(exc).__name__}: {exc}"}
    return report


@router.get("/health")
def health(request: Request) -> JSON:
    """200 with ``status: ok`` when the engine is up (store/ROS may be ``not configured``), else 503."""
    checks: dict[str, HealthCheck] = dict(request.app.state.health_checks)
    report = run_checks(checks)
    for name in ("store", "ros"):
        report.setdefault(name, {"status": "not configured"})
    engine_ok = report.get("engine", {}).get("status") == "ok"
    others_ok = all(v.get("status") in ("ok", "not configured") for v in report.values())
    report["status"] = "ok" if engine_ok and others_ok else ("degraded" if engine_ok else "down")
    return JSON(report, status_code=200 if engine_ok else 503)
