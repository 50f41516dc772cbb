"""One chain, end to end: everything the Information State holds for a correlation id, in time order.

Why: "why did Pepper greet this family late?" crosses four records kept by four parts of the
gateway — the sensor message and the RDF items the ROS ingress mapped it to (``sensor_messages``,
``rdf_events``), the continuous query's result (``query_results``), the decision
(``decisions``) and the robots' action outcomes (``actions``). They share no single key, but they
can be joined: a decision carries its correlation id (the caller's ``X-Request-ID`` /
``traceparent``, the ROS request id, or ``<query>@<window end>`` for a stream decision), a stream
decision names its query and window, a query result names its query and window, the RDF items and
sensor messages carry their stamp (inside the window), and an action outcome names its decision.

Reads only; the decisions are indexed by ``(correlation_id, _id)`` (:mod:`gateway.store.decisions`),
so finding a chain's decisions does not scan the record.
"""

from __future__ import annotations

from datetime import datetime, timezone
from typing import Any

import pymongo
from pymongo.errors import PyMongoError

from gateway.store.store import ACTIONS, QUERY_RESULTS, RDF_EVENTS, SENSOR_MESSAGES, StoreUnavailable

MAX_ITEMS = 200  # per kind of record: a trace is for reading, not for exporting


def _when(doc: dict[str, Any]) -> float:
    """When the record was written (epoch seconds), the order a trace is told in."""
    meta = doc.get("_meta") or {}
    stamp = meta.get("inserted_at")  # a datetime in the database (the journal's epoch seconds, converted)
    if isinstance(stamp, datetime):
        return (stamp if stamp.tzinfo else stamp.replace(tzinfo=timezone.utc)).timestamp()
    if isinstance(stamp, (int, float)):
        return float(stamp)
    return 0.0


def _item(kind: str, doc: dict[str, Any]) -> dict[str, Any]:
    body = {k: v for k, v in doc.items() if k != "_meta"}
    body["_id"] = str(body.get("_id"))
    t = _when(doc)
    return {"kind": kind, "t": t, "at": datetime.fromtimestamp(t, timezone.utc).isoformat(timespec="milliseconds")
            .replace("+00:00", "Z"), "record": body}


def trace(db: Any, correlation_id: str) -> dict[str, Any] | None:
    """The chain of ``correlation_id``: ``{"correlation_id", "items": [{"kind", "at", "t",
    "since_previous_ms", "record"}], "hops": [...]}`` oldest first; None when nothing has it."""
    try:
        decisions = list(db["decisions"].find({"correlation_id": correlation_id}).sort("_id", pymongo.ASCENDING)
                         .limit(MAX_ITEMS))
        if not decisions:
            return None
        items = [_item("decision", d) for d in decisions]
        ids = [str(d["_id"]) for d in decisions]
        items += [_item("action", a) for a in db[ACTIONS].find({"decision_id": {"$in": ids}}).limit(MAX_ITEMS)]
        for decision in decisions:
            items += _stream_items(db, decision)
    except PyMongoError as exc:
        raise StoreUnavailable(f"Information State unreachable: {type(exc).__name__}: {exc}") from exc
    items.sort(key=lambda i: (i["t"], _ORDER[i["kind"]]))
    previous = None
    for item in items:
        item["since_previous_ms"] = None if previous is None else round((item["t"] - previous) * 1000, 3)
        previous = item["t"]
    hops = [{"from": a["kind"], "to": b["kind"], "ms": b["since_previous_ms"]} for a, b in zip(items, items[1:])
            if a["kind"] != b["kind"]]
    return {"correlation_id": correlation_id, "items": items, "hops": hops,
            "total_ms": round((items[-1]["t"] - items[0]["t"]) * 1000, 3) if items else 0.0}


_ORDER = {"sensor_message": 0, "rdf_item": 1, "query_result": 2, "decision": 3, "action": 4}


def _stream_items(db: Any, decision: dict[str, Any]) -> list[dict[str, Any]]:
    """For a stream decision: its query's result for the window, and the RDF items and sensor
    messages stamped inside that window."""
    context = decision.get("context") or {}
    query, window = context.get("query"), context.get("window") or {}
    if decision.get("origin") != "stream" or not query or "end" not in window:
        return []
    start, end = window.get("start", window["end"]), window["end"]
    stamped = {"stamp_ms": {"$gte": start, "$lte": end}}
    out = [_item("query_result", r) for r in db[QUERY_RESULTS].find({"query": query, "window.end": end})
           .limit(MAX_ITEMS)]
    out += [_item("rdf_item", r) for r in db[RDF_EVENTS].find(stamped).limit(MAX_ITEMS)]
    out += [_item("sensor_message", r) for r in db[SENSOR_MESSAGES].find(stamped).limit(MAX_ITEMS)]
    return out
