"""``/api/decisions``: the one decision record, from the Information State.

Every fire from every origin (``rest``, ``kie``, ``stream``, ``ros``, ``workflow``) is a decision
with an id, kept in MongoDB (:mod:`gateway.store.decisions`), so any gateway process answers for
any decision, also after restarts. Newest first, paged with an opaque cursor.

    GET /api/decisions?ruleset=&version=&origin=&rule=&since=&until=&limit=&cursor=
        -> {"decisions": [...], "next_cursor": "…" | null}
    GET /api/decisions/{decision_id}   one decision with the outcomes of its robot actions
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Query

from gateway.api.deps import Caller, DecisionsDep, iso_datetime
from gateway.api.errors import ApiError
from gateway.api.jsonio import JSON, JsonRoute
from gateway.store.store import StoreError, StoreUnavailable

router = APIRouter(tags=["decisions"], route_class=JsonRoute)

ORIGINS = ("rest", "kie", "stream", "ros", "workflow", "api")


@router.get("/api/decisions")
def list_decisions(
    decisions: DecisionsDep,
    _: Caller,
    ruleset: str | None = Query(None, max_length=200),
    version: int | None = Query(None, ge=1),
    origin: str | None = Query(None, max_length=40, description=f"one of {', '.join(ORIGINS)}"),
    rule: str | None = Query(None, max_length=500, description="decisions in which this rule fired"),
    since: str | None = Query(None, description="ISO-8601, inclusive"),
    until: str | None = Query(None, description="ISO-8601, exclusive"),
    limit: int = Query(50, ge=1, le=1000),
    cursor: str | None = Query(None, max_length=64, description="next_cursor of the previous page"),
) -> JSON:
    """Decisions newest first: decision_id, origin, correlation_id, ruleset, version, facts, fired,
    actions, at, process."""
    start, end = iso_datetime("since", since), iso_datetime("until", until)
    if start and end and start >= end:
        raise ApiError(422, "since must be before until", errors=[{"field": "since", "message": "after until"}])
    try:
        page, next_cursor = decisions.find(ruleset=ruleset, version=version, origin=origin, rule=rule, since=start,
                                           until=end, limit=limit, cursor=cursor)
    except StoreError as exc:
        raise ApiError(422, str(exc), errors=[{"field": "cursor", "message": str(exc)}]) from None
    except StoreUnavailable as exc:
        raise ApiError(503, str(exc)) from None
    return JSON({"decisions": page, "next_cursor": next_cursor})


@router.get("/api/decisions/{decision_id}")
def get_decision(decision_id: str, decisions: DecisionsDep, _: Caller) -> JSON:
    """One decision with ``outcomes``: what the robots did for it (status, attempts, message)."""
    return JSON(recorded_decision(decisions, decision_id))


def recorded_decision(decisions: Any, decision_id: str) -> dict[str, Any]:
    """The recorded decision ``decision_id``, or ApiError 404 (none) / 503 (the store is unreachable)."""
    try:
        found = decisions.get(decision_id)
    except StoreUnavailable as exc:
        raise ApiError(503, str(exc)) from None
    if found is None:
        raise ApiError(404, f"no decision {decision_id!r}", decision_id=decision_id)
    return found
