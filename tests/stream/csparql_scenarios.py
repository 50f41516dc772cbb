"""Synthetic entrance-sensor scenarios (Kinect distances per person) for the stream tests and bench."""

from __future__ import annotations

import random
from collections.abc import Callable
from pathlib import Path

from gateway.rdf import Mapper
from gateway.rdf.mapping import mappings_from_folder

ROOT = Path(__file__).resolve().parents[2]
CUSTOMER_QUERY = (ROOT / "ontology" / "queries" / "customer_detection.rq").read_text(encoding="utf-8")
ENTRANCE = "http://printeps.org/cafe/entrance"
PRINTEPS = "http://printeps.org/cafe/entrance/"

Track = Callable[[float], float | None]  # seconds since start -> distance in metres (None: not seen)


def approaching(start: float, speed: float) -> Track:
    return lambda t: round(start - speed * t, 3)


def leaving(start: float, speed: float) -> Track:
    return lambda t: round(start + speed * t, 3)


def walking_past(distance: float, noise: float = 0.0, seed: int = 0) -> Track:
    rnd = random.Random(seed)
    return lambda t: round(distance + rnd.uniform(-noise, noise), 3)


def messages(tracks: dict[str, Track], hz: float, seconds: float, t0_ms: int = 0) -> list[tuple[int, dict]]:
    """(timestamp ms, Entrance message) at ``hz`` readings per second for ``seconds``."""
    out = []
    n = int(round(seconds * hz))
    for k in range(n):
        t = k / hz
        ts = t0_ms + int(round(t * 1000))
        customers = []
        for cid, track in tracks.items():
            d = track(t)
            if d is not None:
                customers.append({"id": cid, "distance": d})
        out.append((ts, {"id": "entrance1", "number_of_customers": len(customers), "customers": customers}))
    return out


def replay(engine, msgs: list[tuple[int, dict]], stream: str = ENTRANCE, flush_ms: int | None = None) -> list[dict]:
    """Push the messages, collect result events (and close the last windows with a heartbeat)."""
    events: list[dict] = []
    token = engine.subscribe(events.append)
    mapper = Mapper(mappings_from_folder(ROOT / "ontology" / "mappings"))
    try:
        for ts, msg in msgs:
            engine.push(stream, ts, mapper.map(msg, ts, "entrance"))
        if flush_ms is not None:
            engine.advance(flush_ms)
    finally:
        engine.unsubscribe(token)
    return [e for e in events if e["kind"] == "result"]


def detections(events: list[dict]) -> dict[int, set[str]]:
    """Window end (ms) -> customer ids detected in that window (windows without a detection left out:
    every window is reported, empty ones included)."""
    return {e["window"]["end"]: {r["s"].rsplit("/", 1)[-1] for r in e["rows"]} for e in events if e["rows"]}


def nonempty(events: list[dict]) -> list[dict]:
    """The result events with at least one solution."""
    return [e for e in events if e["kind"] == "result" and e["rows"]]
