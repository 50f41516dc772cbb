"""GET /api/state/{collection}: read the Information State over REST, with filters.

Why a thin router: all querying lives in gateway.store; this only turns query parameters into a
store query.

    GET /api/state/actions?type=printeps/Action&since=2026-11-22T00:00:00Z&limit=20&robot=pepper
Reserved parameters: type, since, until (ISO-8601), limit (1..1000), order (newest|oldest).
Every other parameter is an equality filter on a (dotted) field; "2" matches 2 or "2".
"""

from __future__ import annotations

import json
from typing import Any

from fastapi import APIRouter, HTTPException, Query, Request
from fastapi.encoders import jsonable_encoder

from gateway.api.deps import Caller, StoreDep, iso_datetime
from gateway.store.store import MAX_LIMIT, StoreError, StoreUnavailable
from gateway.api.jsonio import JsonRoute

router = APIRouter(prefix="/api/state", tags=["information-state"], route_class=JsonRoute)

RESERVED = {"type", "since", "until", "limit", "order"}


def _filter_value(raw: str) -> Any:
    """Match both the typed value and the raw string, since query strings carry no types."""
    try:
        typed = json.loads(raw)
    except ValueError:
        return raw
    if isinstance(typed, (int, float, bool)) or typed is None:
        return {"$in": [typed, raw]}
    return raw


@router.get("/{collection}")
def read_state(request: Request, collection: str, store: StoreDep, _: Caller, type: str | None = None,
               since: str | None = None, until: str | None = None, limit: int = Query(100, ge=1, le=MAX_LIMIT),
               order: str = Query("newest", pattern="^(newest|oldest)$")) -> dict[str, Any]:
    """Documents of one collection, newest first by default, with ``_meta`` and ``_id`` as a string."""
    filters = {k: _filter_value(v) for k, v in request.query_params.items() if k not in RESERVED}
    try:
        docs = store.query(collection, type=type, since=iso_datetime("since", since), until=iso_datetime("until", until),
                           filters=filters, limit=limit, newest_first=order == "newest")
    except StoreError as exc:
        raise HTTPException(422, str(exc)) from None
    except StoreUnavailable as exc:
        raise HTTPException(503, str(exc)) from None
    return {"collection": collection, "count": len(docs), "documents": jsonable_encoder(docs),
            "health": store.health()}
