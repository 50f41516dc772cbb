"""The live feed: what this gateway process sees happen, as one ordered list of small events.

Why: the teahouse owner wants to watch the reception as it plays (the workbench's Live view,
``GET /api/live``): who is near the entrance, what the stream queries detected, which rules fired
(with the decision to open) and what the robots did. Each of those is already announced somewhere
in the gateway; the composition root (:mod:`gateway.app`) wires these hooks to one feed:

- ``on_stream_item(stream, timestamp_ms, triples)`` — a stream engine input listener: each person's
  distance in a message on the entrance stream (``reading_streams``) becomes a ``reading``
  (``{"t", "stream", "distances": {person: m}}``; ``t`` is the sensor's time, ms);
- ``on_stream_event(event)`` — a stream engine subscriber: a non-empty query result becomes a
  ``detection`` (``{"query", "window", "rows", "solutions"}``); a window a rule binding skipped
  because its rules were still firing an earlier one, a ``skipped`` (``{"query", "ruleset", "window", "reason"}``);
- ``on_engine_event(kind, payload)`` — a rules engine listener: each fire is a ``decision``
  (``{"decision_id", "ruleset", "version", "origin", "fired", "actions", "query"}``);
- ``on_outcome(outcome)`` — an action router listener, and ``on_workflow_record(kind, payload)`` — a
  workflow recorder: what a robot (or a person) was asked to do and how it went, an ``action``.

Every event gets ``kind``, ``seq`` (this feed's order) and ``at`` (wall-clock ms). The last events of
each kind are kept (``kept`` per kind) and replayed to late joiners, so a browser that opens the view
mid-scenario still draws the last minute. Subscribers read from their own bounded queue: a slow or
stalled browser loses its oldest events (counted) and never blocks the gateway's threads.

One process, one feed, showing the whole gateway: with several worker processes or hosts, what
the *others* decide, do and detect reaches this feed through the Information State while someone
watches (:mod:`gateway.store.live_relay`, wired by the composition root); readings appear in the
process that runs the ROS node.

Plain Python, no web framework: the REST route (:mod:`gateway.api.routes.live`) only turns a
subscription into Server-Sent Events.
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
import uuid
from collections import deque
from typing import Any, Callable

from gateway.config import ENTRANCE_STREAM
from gateway.rdf.terms import PRINTEPS

log = logging.getLogger(__name__)

KINDS = ("reading", "detection", "decision", "action", "skipped")
DISTANCE = PRINTEPS + "distance"
POSITION_AT_TIME = PRINTEPS + "positionAtTime"
MAX_ROWS = 50  # rows of a detection shown live (the full result stays in /api/queries/{name}/results)
ROBOT_KINDS = ("ros_service", "ros_topic", "manual")  # workflow steps that are someone doing something

Event = dict[str, Any]


def local_name(iri: str) -> str:
    """``http://printeps.org/cafe/entrance/g1a`` → ``g1a`` (what the owner calls the person)."""
    for sep in ("#", "/", ":"):
        if sep in iri:
            iri = iri.rsplit(sep, 1)[1] or iri
    return iri


def distances_in(triples: list[Any]) -> dict[str, float]:
    """Each person's distance in one sensor message: ``person positionAtTime node . node distance d``
    (the entrance mapping's timed readings), or ``person distance d`` directly."""
    owner: dict[Any, Any] = {}
    found: list[tuple[Any, Any]] = []
    for s, p, o in triples:
        predicate = getattr(p, "value", None)
        if predicate == POSITION_AT_TIME:
            owner[o] = s
        elif predicate == DISTANCE:
            found.append((s, o))
    out: dict[str, float] = {}
    for node, value in found:
        try:
            distance = float(getattr(value, "value", value))
        except (TypeError, ValueError):
            continue  # not a number: the mapping checks report it, the plot skips it
        person = owner.get(node, node)
        out[local_name(str(getattr(person, "value", person)))] = distance
    return out


class Subscription:
    """One reader of the feed: a bounded queue filled by the gateway's threads, drained by the reader.

    ``wake`` is called (from the gateway's thread) after each event is queued — the SSE route uses
    it to wake its asyncio task; it must not block."""

    def __init__(self, feed: LiveFeed, size: int, wake: Callable[[], None] | None) -> None:
        self._feed = feed
        self._queue: deque[Event] = deque()
        self._size = size
        self._lock = threading.Lock()
        self._wake = wake
        self.dropped = 0
        self.closed = False  # the feed closed (the server is stopping): the reader should end

    def put(self, event: Event) -> None:
        with self._lock:
            if len(self._queue) >= self._size:
                self._queue.popleft()  # the oldest goes: the live picture stays current
                self.dropped += 1
            self._queue.append(event)
        if self._wake is not None:
            try:
                self._wake()
            except Exception:  # a closed reader (its loop gone) must not disturb the gateway
                log.debug("waking a live subscriber failed", exc_info=True)

    def take(self) -> tuple[list[Event], int]:
        """Everything queued so far and how many events were dropped since the last take."""
        with self._lock:
            events = list(self._queue)
            self._queue.clear()
            dropped, self.dropped = self.dropped, 0
        return events, dropped

    def close(self) -> None:
        self._feed.unsubscribe(self)

    def end(self) -> None:
        """The feed is closing: wake the reader so it can finish its response."""
        self.closed = True
        if self._wake is not None:
            try:
                self._wake()
            except Exception:
                log.debug("waking a live subscriber failed", exc_info=True)


class LiveFeed:
    """The feed of one gateway process (see the module docstring)."""

    def __init__(self, *, kept: int = 500, queue_size: int = 2000, kept_by_kind: dict[str, int] | None = None,
                 reading_streams: tuple[str, ...] = (ENTRANCE_STREAM,)) -> None:
        self.reading_streams = frozenset(reading_streams)
        self.id = uuid.uuid4().hex[:8]  # tells a reconnecting browser whether its Last-Event-ID is ours
        self._kept = {kind: (kept_by_kind or {}).get(kind, kept) for kind in KINDS}
        self._recent: dict[str, deque[Event]] = {kind: deque(maxlen=n) for kind, n in self._kept.items()}
        self._subscribers: list[Subscription] = []
        self._queue_size = queue_size
        self._seq = itertools.count(1)
        self._lock = threading.Lock()
        self.published = {kind: 0 for kind in KINDS}
        self.closed = False

    # -- publishing --------------------------------------------------------------------------------
    def publish(self, kind: str, data: Event) -> Event:
        """Add one event of ``kind`` (one of :data:`KINDS`) and hand it to every subscriber."""
        if kind not in self._recent:
            raise ValueError(f"unknown live event kind {kind!r}; known: {', '.join(KINDS)}")
        with self._lock:
            event = {"kind": kind, "seq": next(self._seq), "at": int(time.time() * 1000), **data}
            self._recent[kind].append(event)
            self.published[kind] += 1
            subscribers = list(self._subscribers)
        for subscriber in subscribers:  # outside the lock: wake-ups may take a moment
            subscriber.put(event)
        return event

    def subscribe(self, wake: Callable[[], None] | None = None, *, after: int | None = None,
                  replay: bool = True) -> Subscription:
        """A new reader whose queue starts with the kept events (all, or those after seq ``after``;
        none without ``replay``), oldest first; later events follow with no gap and no repeat."""
        subscription = Subscription(self, self._queue_size, None)
        with self._lock:
            for event in self.recent(after=after, locked=True) if replay else []:
                subscription.put(event)
            self._subscribers.append(subscription)
        subscription._wake = wake
        subscription.closed = self.closed
        return subscription

    def close(self) -> None:
        """End every reader (a stopping server must not wait for browsers that never hang up)."""
        with self._lock:
            self.closed = True
            subscribers, self._subscribers = list(self._subscribers), []
        for subscriber in subscribers:
            subscriber.end()

    def unsubscribe(self, subscription: Subscription) -> None:
        with self._lock:
            if subscription in self._subscribers:
                self._subscribers.remove(subscription)

    def recent(self, *, after: int | None = None, locked: bool = False) -> list[Event]:
        """The kept events of every kind, in feed order."""
        if not locked:
            with self._lock:
                return self.recent(after=after, locked=True)
        events = [e for kept in self._recent.values() for e in kept if after is None or e["seq"] > after]
        return sorted(events, key=lambda e: e["seq"])

    def stats(self) -> dict[str, Any]:
        with self._lock:
            return {"id": self.id, "subscribers": len(self._subscribers), "published": dict(self.published),
                    "kept": {kind: len(kept) for kind, kept in self._recent.items()}}

    # -- hooks (wired by gateway.app) ----------------------------------------------------------------
    def on_stream_item(self, stream: str, timestamp_ms: int, triples: list[Any]) -> None:
        """Stream engine input listener: the people's distances in one entrance message, if it has any."""
        if stream not in self.reading_streams:
            return
        distances = distances_in(triples)
        if distances:
            self.publish("reading", {"stream": stream, "t": int(timestamp_ms), "distances": distances})

    def on_stream_event(self, event: dict[str, Any]) -> None:
        """Stream engine subscriber: a query result with solutions is a detection; a window a rule
        binding skipped (its rules still firing an earlier one) is said as ``skipped``."""
        if event.get("kind") == "skipped":
            self.publish("skipped", {key: event.get(key) for key in ("query", "ruleset", "window", "reason")})
            return
        if event.get("kind") != "result" or not event.get("solutions"):
            return
        rows = list(event.get("rows") or [])
        self.publish("detection", {"query": event.get("query"), "window": event.get("window"),
                                   "solutions": event.get("solutions"), "rows": rows[:MAX_ROWS],
                                   "variables": event.get("variables")})

    def on_engine_event(self, kind: str, payload: dict[str, Any]) -> None:
        """Rules engine listener: every fire is a decision (with the id the decision record has)."""
        if kind != "fire":
            return
        context = payload.get("context") or {}
        self.publish("decision", {
            "decision_id": payload.get("decision_id"), "ruleset": payload.get("ruleset"),
            "version": payload.get("version"), "origin": payload.get("origin"),
            "correlation_id": payload.get("correlation_id"), "fired": list(payload.get("fired") or []),
            "actions": list(payload.get("actions") or []), "query": context.get("query"),
            "window": context.get("window"),
        })

    def on_outcome(self, outcome: dict[str, Any]) -> None:
        """Action router listener: an action of a decision and how it went."""
        action = outcome.get("action") or {}
        self.publish("action", {
            "source": "rules", "module": action.get("module"), "params": action.get("params") or {},
            "status": outcome.get("status"), "message": outcome.get("message"),
            "decision_id": outcome.get("decision_id"), "ruleset": outcome.get("ruleset"),
            "duration_ms": outcome.get("duration_ms"),
        })

    def on_workflow_record(self, kind: str, payload: dict[str, Any]) -> None:
        """Workflow recorder: a step in which a robot or a person was asked to do something."""
        if kind != "workflow_step" or payload.get("type") != "module" or payload.get("kind") not in ROBOT_KINDS:
            return
        self.publish("action", {
            "source": "workflow", "workflow": payload.get("workflow"), "run_id": payload.get("run_id"),
            "step": payload.get("step_id"), "module": payload.get("module"), "actor": payload.get("actor"),
            "params": payload.get("params") or {}, "status": payload.get("status"),
            "message": payload.get("error"), "duration_ms": payload.get("duration_ms"),
        })
