"""Customer entry detection over the entrance stream: the papers' CustomerDetectionQuery semantics.

The stream side (gateway.stream, C-SPARQL over RDF streams) is the real implementation. This
module holds (a) the small interface the node needs from it and (b) a plain-Python evaluation of
the same query, used when gateway.stream is not installed and in unit tests:

    every STEP (1 s), over the readings of the last RANGE (3 s), per customer ?s: pairs of readings
    (later d1, earlier d2) with d2 - d1 > 0.1 m; detected when COUNT(pairs) > 1 and AVG(d1) < the
    distance to the entrance (3.3 m, from the teahouse ontology).

The window is evaluated when a reading arrives whose stamp is a STEP past the previous evaluation,
over (stamp - RANGE, stamp]; so the reading that completes a detection triggers it at once.
"""

from __future__ import annotations

from collections import defaultdict, deque
from typing import Any, Protocol


class EventDetector(Protocol):
    """What the node needs from a stream processor: readings in, detection events out."""

    def push(self, reading: dict[str, Any]) -> list[dict[str, Any]]:
        """Add one validated Entrance reading (``stamp`` in seconds); return events it completes."""
        ...


class EntryDetector:
    """The CustomerDetectionQuery in plain Python (RANGE/STEP windows, pairs COUNT and AVG)."""

    query_name = "CustomerDetectionQuery"

    def __init__(self, range_s: float = 3.0, step_s: float = 1.0, min_difference: float = 0.1,
                 distance_to_entrance: float = 3.3) -> None:
        self.range_s = range_s
        self.step_s = step_s
        self.min_difference = min_difference
        self.distance_to_entrance = distance_to_entrance
        self._readings: deque[tuple[float, str, float]] = deque()  # (stamp, customer id, distance)
        self._next_eval: float | None = None

    def push(self, reading: dict[str, Any]) -> list[dict[str, Any]]:
        t = float(reading["stamp"])
        for c in reading.get("customers", []):
            self._readings.append((t, c["id"], float(c["distance"])))
        while self._readings and self._readings[0][0] <= t - self.range_s:
            self._readings.popleft()
        if self._next_eval is None:
            self._next_eval = t + self.step_s
            return []
        if t + 1e-9 < self._next_eval:
            return []
        self._next_eval = t + self.step_s
        return self.evaluate(t)

    def evaluate(self, t: float) -> list[dict[str, Any]]:
        """One window (t - RANGE, t]: a detection event per customer that is approaching and close."""
        per: dict[str, list[tuple[float, float]]] = defaultdict(list)
        for ts, cid, d in self._readings:
            if ts > t - self.range_s:
                per[cid].append((ts, d))
        events = []
        for cid, series in per.items():
            pairs = [d1 for ts1, d1 in series for ts2, d2 in series if ts1 > ts2 and d2 - d1 > self.min_difference]
            if len(pairs) > 1 and sum(pairs) / len(pairs) < self.distance_to_entrance:
                events.append({"query": self.query_name, "s": cid, "cnt": len(pairs),
                               "distance": sum(pairs) / len(pairs), "window_end": t})
        return events
