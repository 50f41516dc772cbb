"""The messages of one stream kept for one query, and the contents of its windows.

Why panes: a sliding window ``[RANGE r STEP s]`` sees every message ``r / s`` times. The buffer
cuts time into panes of ``gcd(step, ranges)`` ms (window bounds always fall on pane bounds); a
pane that lies before the query's watermark (``closed_until``: later data for it is late and
dropped) can no longer change, so its content — each triple with its latest timestamp — is built
once and reused by every window that covers it (and the fast path caches its encoded columns on
it). A window is then a few ``dict.update`` calls, whatever its range.
"""

from __future__ import annotations

import bisect
from collections.abc import Iterable
from math import gcd
from typing import Any

from gateway.rdf.terms import Triple


class Segment:
    """The stream triples of one stretch of time, each with its latest timestamp.

    ``sealed`` segments never change; ``cache`` holds what evaluators derived from them (the fast
    path's encoded columns)."""

    __slots__ = ("stamped", "sealed", "cache")

    def __init__(self, stamped: dict[Triple, int], sealed: bool) -> None:
        self.stamped = stamped
        self.sealed = sealed
        self.cache: dict[Any, Any] = {}

    def __len__(self) -> int:
        return len(self.stamped)


class StreamBuffer:
    """The timestamp-ordered messages of one stream kept for one query."""

    def __init__(self, stream: str) -> None:
        self.stream = stream
        self.stamps: list[int] = []
        self.items: list[list[Triple]] = []
        self.n_triples = 0
        self.pane_ms: int | None = None
        self._panes: dict[int, Segment] = {}

    # -- content ---------------------------------------------------------------------------------
    def add(self, ts: int, triples: list[Triple]) -> None:
        if not self.stamps or ts >= self.stamps[-1]:
            self.stamps.append(ts)
            self.items.append(triples)
        else:
            i = bisect.bisect_right(self.stamps, ts)
            self.stamps.insert(i, ts)
            self.items.insert(i, triples)
        self.n_triples += len(triples)

    def drop_first(self, count: int) -> None:
        if count <= 0:
            return
        self.n_triples -= sum(len(x) for x in self.items[:count])
        del self.stamps[:count]
        del self.items[:count]
        first = self.stamps[0] if self.stamps else None
        for start in [p for p in self._panes if first is None or p < first]:
            del self._panes[start]  # a pane that lost messages is no longer right

    def evict(self, before: int | None, keep_triples: int = 0) -> None:
        """Drop messages older than ``before`` (None: no time window needs them) as long as at least
        ``keep_triples`` triples remain after them (for count windows)."""
        limit = len(self.stamps) if before is None else bisect.bisect_left(self.stamps, before)
        drop, remaining = 0, self.n_triples
        while drop < limit and remaining - len(self.items[drop]) >= keep_triples:
            remaining -= len(self.items[drop])
            drop += 1
        if drop:
            self.n_triples -= sum(len(x) for x in self.items[:drop])
            del self.stamps[:drop]
            del self.items[:drop]
        if before is not None and self.pane_ms:
            for start in [p for p in self._panes if p + self.pane_ms <= before]:
                del self._panes[start]

    def set_pane(self, ms: int | None) -> None:
        if ms != self.pane_ms:
            self.pane_ms = ms
            self._panes.clear()

    def first_at_or_after(self, start: int, until: int) -> int | None:
        """The oldest timestamp in ``[start, until)`` (None: nothing there)."""
        i = bisect.bisect_left(self.stamps, start)
        return self.stamps[i] if i < len(self.stamps) and self.stamps[i] < until else None

    # -- windows ---------------------------------------------------------------------------------
    def time_segments(self, start: int, until: int, sealed_until: int | None) -> list[Segment]:
        """The non-empty segments covering ``[start, until)``; whole panes before ``sealed_until``
        come from (and go to) the pane cache."""
        pane = self.pane_ms
        if not pane or start % pane:
            seg = self._build(start, until, False)
            return [seg] if seg.stamped else []
        out: list[Segment] = []
        p = start
        while p < until:
            end = p + pane
            if end <= until and sealed_until is not None and end <= sealed_until:
                seg = self._panes.get(p)
                if seg is None:
                    seg = self._build(p, end, True)
                    self._panes[p] = seg
            else:
                seg = self._build(p, min(end, until), False)
            if seg.stamped:
                out.append(seg)
            p = end
        return out

    def _build(self, start: int, until: int, sealed: bool) -> Segment:
        i = bisect.bisect_left(self.stamps, start)
        j = bisect.bisect_left(self.stamps, until)
        stamped: dict[Triple, int] = {}
        for k in range(i, j):  # ascending time: a later occurrence overwrites an earlier one
            stamped.update(dict.fromkeys(self.items[k], self.stamps[k]))
        return Segment(stamped, sealed)

    def last_triples(self, n: int, until: int) -> Segment:
        """The last ``n`` triple occurrences with ``ts < until`` (a count window)."""
        stop = bisect.bisect_left(self.stamps, until)
        picked: list[tuple[Triple, int]] = []
        remaining = n
        for i in range(stop - 1, -1, -1):
            items = self.items[i]
            take = items if len(items) <= remaining else items[len(items) - remaining:]
            ts = self.stamps[i]
            picked.extend((t, ts) for t in take)
            remaining -= len(take)
            if remaining == 0:
                break
        stamped: dict[Triple, int] = {}
        for t, ts in reversed(picked):  # oldest first, so the latest timestamp wins
            stamped[t] = ts
        return Segment(stamped, False)


def pane_size(step: int | None, ranges: Iterable[int]) -> int | None:
    """The pane length for windows that close at multiples of ``step`` with these ranges."""
    if step is None:
        return None
    size = step
    for r in ranges:
        size = gcd(size, r)
    return size


def merge(segments: Iterable[Segment]) -> dict[Triple, int]:
    """Segments of one stream, oldest first, into one ``{triple: latest timestamp}``."""
    merged: dict[Triple, int] = {}
    for seg in segments:
        merged.update(seg.stamped)  # later segments hold later timestamps
    return merged


def merge_latest(parts: list[dict[Triple, int]]) -> dict[Triple, int]:
    """Several streams' contents into one, keeping each triple's latest timestamp."""
    parts = [p for p in parts if p]
    if not parts:
        return {}
    if len(parts) == 1:
        return parts[0]
    parts.sort(key=len, reverse=True)
    merged = dict(parts[0])
    for part in parts[1:]:
        for t, ts in part.items():
            if merged.get(t, -(1 << 62)) <= ts:
                merged[t] = ts
    return merged
