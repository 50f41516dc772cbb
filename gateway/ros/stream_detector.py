"""The entry detector backed by the stream package: Entrance readings → RDF stream → C-SPARQL.

Why an adapter: gateway.stream is the project's C-SPARQL engine (the papers' CustomerDetectionQuery
in ontology/queries/, ?distance_to_entrance bound from the ontology). The node only needs
``push(reading) -> events``; this maps the reading to RDF with the built-in ``entrance`` mapping,
pushes it on the entrance stream and returns the rows of every window that reading closed.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

ENTRANCE_STREAM = "http://printeps.org/cafe/entrance"


class StreamDetector:
    """``push(reading)``: one message on the entrance stream; result rows as detection events."""

    def __init__(self, engine: Any, mapper: Any, stream: str = ENTRANCE_STREAM) -> None:
        self.engine = engine
        self.mapper = mapper
        self.stream = stream
        self.last_rdf: list[list[str]] = []
        self._collected: list[dict[str, Any]] = []
        self._lock = threading.Lock()
        engine.subscribe(self._on_event)

    def _on_event(self, event: dict[str, Any]) -> None:
        self._collected.append(event)

    def push(self, reading: dict[str, Any]) -> list[dict[str, Any]]:
        message = {"id": reading["id"], "number_of_customers": reading.get("number_of_customers", 0),
                   "has_customers": [{k: v for k, v in c.items() if k in ("id", "distance", "age", "gender")}
                                     for c in reading.get("customers", [])]}
        ts = int(round(float(reading["stamp"]) * 1000))
        with self._lock:
            self._collected.clear()
            triples = self.mapper.map(message, ts, mapping="entrance")
            self.last_rdf = [[str(t) for t in triple] for triple in triples]
            self.engine.push(self.stream, ts, triples)
            events = list(self._collected)
        out = []
        for ev in events:
            if ev.get("kind") != "result":
                continue
            for row in ev.get("rows", []):
                out.append({"query": ev.get("query"), "s": str(row.get("s", "")).rsplit("/", 1)[-1],
                            "cnt": row.get("cnt"), "distance": float(row.get("distance", 0.0)),
                            "window_end": ev.get("window", {}).get("end"), "path": ev.get("path")})
        return out


def stream_detector(settings: Any) -> StreamDetector:
    """A stream engine with the .rq queries of settings.streams.queries_dir registered."""
    from gateway.rdf.mapping import Mapper
    from gateway.stream import StreamEngine

    cfg = settings.streams
    engine = StreamEngine(cfg)
    for path in sorted(Path(cfg.queries_dir).glob("*.rq")):
        engine.register(path.read_text(encoding="utf-8"), replace=True)
    return StreamDetector(engine, Mapper())
