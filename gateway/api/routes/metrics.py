"""``GET /metrics``: the Prometheus text format of the app's counters (see :mod:`gateway.api.metrics`)."""

from __future__ import annotations

from fastapi import APIRouter
from fastapi.responses import Response
from prometheus_client import CONTENT_TYPE_LATEST

from gateway.api.deps import EngineDep, MetricsDep
from gateway.api.jsonio import JsonRoute

router = APIRouter(tags=["operations"], route_class=JsonRoute)


@router.get("/metrics", response_class=Response, responses={200: {"content": {"text/plain": {}}}})
async def metrics(engine: EngineDep, counters: MetricsDep) -> Response:
    """printeps_fires_total, printeps_fire_seconds, printeps_deploys_total, printeps_rulesets, …"""
    counters.rulesets.set(len(engine.live_versions()))
    return Response(counters.render(), media_type=CONTENT_TYPE_LATEST)
