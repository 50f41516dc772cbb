"""Synthetic table-sensor scenarios (TeahouseObject readings) for the leaving-seat tests and bench.

The proposed mapping of printeps_interfaces/msg/TeahouseObject (id, type, location, x, y,
distance, stamp) to RDF, written with the existing NodeMap of gateway/rdf/mapping.py: one message
per object a table sensor sees (a customer, a member of staff, the table itself), timestamped
with ``stamp``::

    printeps:<id> printeps:objectType "<type>" ; printeps:location "<location>" ;
                  printeps:positionAtTime printeps:<id>_t<ms> .
    printeps:<id>_t<ms> printeps:x <x> ; printeps:y <y> ; printeps:distance <distance> .

``location`` is the id of a Location (the ontology gives each table a ``printeps:locationId``).
"""

from __future__ import annotations

from pathlib import Path

from gateway.rdf.mapping import Mapper, NodeMap

ROOT = Path(__file__).resolve().parents[2]
LEAVING_SEAT_QUERY = (ROOT / "ontology" / "queries" / "leaving_seat.rq").read_text(encoding="utf-8")
TABLES = "http://printeps.org/cafe/tables"
P = "http://printeps.org/cafe/entrance/"

TEAHOUSE_OBJECT = NodeMap(
    subject="printeps:{id}",
    fields={"type": "printeps:objectType", "location": "printeps:location"},
    timed={"x": "printeps:x", "y": "printeps:y", "distance": "printeps:distance"},
)


def mapper() -> Mapper:
    return Mapper({"teahouse_object": TEAHOUSE_OBJECT})


def teahouse_object(obj_id: str, kind: str, location: str, distance: float = 0.4) -> dict:
    return {"id": obj_id, "type": kind, "location": location, "x": 1.25, "y": 2.5, "distance": distance}


def messages(presence: dict[str, list[tuple[str, str, float, float]]], tables: list[str], hz: float,
             seconds: float, t0_ms: int = 0) -> list[tuple[int, dict]]:
    """(timestamp ms, TeahouseObject) at ``hz`` per table: each table itself (a heartbeat of its
    sensor) and every person present: ``presence[table] = [(person id, type, from s, to s), …]``."""
    out = []
    for k in range(int(round(seconds * hz))):
        t = k / hz
        ts = t0_ms + int(round(t * 1000))
        for table in tables:
            out.append((ts, teahouse_object(table, "Table", table, 0.0)))
            for person, kind, start, end in presence.get(table, []):
                if start <= t < end:
                    out.append((ts, teahouse_object(person, kind, table)))
    return out


def replay(engine, msgs: list[tuple[int, dict]], flush_ms: int | None = None) -> list[dict]:
    """Push the readings; the result events (heartbeat to ``flush_ms`` at the end)."""
    events: list[dict] = []
    token = engine.subscribe(events.append)
    m = mapper()
    try:
        for ts, msg in msgs:
            engine.push(TABLES, ts, m.map(msg, ts, "teahouse_object"))
        if flush_ms is not None:
            engine.advance(flush_ms)
    finally:
        engine.unsubscribe(token)
    return [e for e in events if e["kind"] == "result"]


def departures(events: list[dict]) -> list[tuple[int, str, int]]:
    """(window end, table, last seen ms) of every reported departure."""
    return [(e["window"]["end"], r["table"].rsplit("/", 1)[-1], r["last_seen"]) for e in events for r in e["rows"]]
