"""Typed dependencies of the routes: the gateway's services and who is calling.

Why here: routes never build or look up services themselves; they declare what they need
(``engine: EngineDep``, ``who: Author``) and FastAPI hands it over from the one gateway the app
was created for (:func:`gateway.api.main.create_app`). The dependencies are ``async`` on purpose:
a sync dependency costs a threadpool hop per request.
"""

from __future__ import annotations

from datetime import datetime, timezone
from typing import Annotated, Any, Mapping

from fastapi import Depends, Request

from gateway.api.auth import Principal, author, caller, kie_caller
from gateway.api.errors import ApiError
from gateway.config import Settings
from gateway.engine import Engine
from gateway.ontology.knowledge import KnowledgeBase
from gateway.stream.engine import StreamEngine
from gateway.stream.services import MappingService, QueryService
from gateway.workflow.service import WorkflowService


def gateway_of(request: Request) -> Any:
    return request.app.state.gateway


async def _gateway(request: Request) -> Any:
    return gateway_of(request)


async def _settings(request: Request) -> Settings:
    return request.app.state.settings


async def _engine(request: Request) -> Engine:
    return gateway_of(request).engine


async def _store(request: Request) -> Any:
    store = gateway_of(request).store
    if store is None:
        raise ApiError(503, "the Information State is not configured on this gateway")
    return store


async def _decisions(request: Request) -> Any:
    decisions = gateway_of(request).decisions
    if decisions is None:
        raise ApiError(503, "decisions are not recorded on this gateway (no Information State)")
    return decisions


async def _knowledge(request: Request) -> KnowledgeBase:
    return gateway_of(request).knowledge


async def _streams(request: Request) -> StreamEngine:
    return gateway_of(request).streams


async def _queries(request: Request) -> QueryService:
    return gateway_of(request).queries


async def _mappings(request: Request) -> MappingService:
    return gateway_of(request).mappings


async def _workflows(request: Request) -> WorkflowService:
    return gateway_of(request).workflows


async def _jobs(request: Request) -> Any:
    return gateway_of(request).jobs


async def _metrics(request: Request) -> Any:
    return request.app.state.metrics


GatewayDep = Annotated[Any, Depends(_gateway)]
SettingsDep = Annotated[Settings, Depends(_settings)]
EngineDep = Annotated[Engine, Depends(_engine)]
StoreDep = Annotated[Any, Depends(_store)]
DecisionsDep = Annotated[Any, Depends(_decisions)]
KnowledgeDep = Annotated[KnowledgeBase, Depends(_knowledge)]
StreamsDep = Annotated[StreamEngine, Depends(_streams)]
QueriesDep = Annotated[QueryService, Depends(_queries)]
MappingsDep = Annotated[MappingService, Depends(_mappings)]
WorkflowsDep = Annotated[WorkflowService, Depends(_workflows)]
MetricsDep = Annotated[Any, Depends(_metrics)]
JobsDep = Annotated[Any, Depends(_jobs)]  # gateway.runtime.jobs.JobService

Caller = Annotated[Principal, Depends(caller)]
Author = Annotated[Principal, Depends(author)]
KieCaller = Annotated[Principal, Depends(kie_caller)]


def iso_datetime(name: str, value: str | None) -> datetime | None:
    """A query parameter in ISO-8601 (naive = UTC), or ApiError 422 naming the parameter."""
    if value is None:
        return None
    try:
        t = datetime.fromisoformat(value.replace("Z", "+00:00"))
    except ValueError:
        raise ApiError(422, f"query parameter {name}={value!r}: not an ISO-8601 date-time",
                       errors=[{"field": name, "message": "not an ISO-8601 date-time"}]) from None
    return t if t.tzinfo else t.replace(tzinfo=timezone.utc)


def wants_async(request: Request) -> bool:
    """The client asked for a job instead of waiting: ``Prefer: respond-async`` (RFC 7240) or ``?async=true``."""
    prefer = request.headers.get("prefer", "").lower()
    flag = request.query_params.get("async", "").lower()
    return "respond-async" in prefer or flag in ("1", "true", "yes")


def correlation_id(request: Request | Mapping[str, str]) -> str | None:
    """The caller's id for a request (or its headers): ``X-Request-ID``, else the trace id of a W3C
    ``traceparent``."""
    headers = request.headers if isinstance(request, Request) else request
    rid = headers.get("x-request-id")
    if rid:
        return rid[:200]
    parent = headers.get("traceparent")
    if parent:
        parts = parent.split("-")
        return parts[1] if len(parts) >= 4 else parent[:200]
    return None
