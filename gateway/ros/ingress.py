"""Sensor messages into the stream engine: check → map to RDF → push on the stream → record.

The one data path of the gateway starts here for ROS: a subscribed message (already a plain dict)
is checked, mapped to timestamped triples by its subscription's mapping and pushed on its RDF
stream — the same stream engine the REST API shows, whose continuous queries and rule bindings
take it from there (window → binding → rules → actions; see :mod:`gateway.ros.dispatch`).
Everything seen is recorded in the Information State: the message (or why it was rejected) and
the RDF it became.

Plain Python, one worker thread: the ROS callbacks only queue (bounded) and return, so the
executor is never held up by a window evaluation or a rule firing.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Any, Callable

from gateway.config import RosSubscription
from gateway.rdf.mapping import Mapper, MappingError
from gateway.ros.convert import stamp_ms
from gateway.ros.readings import ReadingError, validate_entrance
from gateway.store.store import RDF_EVENTS, SENSOR_MESSAGES
from gateway.stream.engine import StreamError

log = logging.getLogger(__name__)

BY = "gateway_node"
Check = Callable[[dict[str, Any]], Any]


def checks(ros_settings: Any) -> dict[str, Check]:
    """The plausibility checks a subscription can name (``check: entrance``)."""
    return {"entrance": lambda m: validate_entrance(m, max_customers=ros_settings.max_customers,
                                                    max_distance_m=ros_settings.max_distance_m)}


class Ingress:
    """Queues messages from ROS callbacks; a worker maps and pushes them in arrival order."""

    def __init__(self, subscriptions: list[RosSubscription], mapper: Mapper, streams: Any, store: Any = None, *,
                 named_checks: dict[str, Check] | None = None, queue_size: int = 1000,
                 on_event: Callable[[str, dict[str, Any]], None] | None = None) -> None:
        self.subscriptions = list(subscriptions)
        self.mapper = mapper
        self.streams = streams
        self.store = store
        self.checks = dict(named_checks or {})
        self.on_event = on_event or (lambda kind, payload: None)
        self.queue: queue.Queue[tuple[int, dict[str, Any], float]] = queue.Queue(maxsize=queue_size)
        self.stats = {"readings": 0, "rejected": 0, "dropped": 0}
        self._stop = threading.Event()
        self._worker = threading.Thread(target=self._work, name="ros-ingress", daemon=True)

    def start(self) -> "Ingress":
        self._worker.start()
        return self

    def stop(self) -> None:
        """Let the worker finish the message in hand, then stop."""
        self._stop.set()
        if self._worker.is_alive() and threading.current_thread() is not self._worker:
            self._worker.join(timeout=5.0)

    def enqueue(self, index: int, message: dict[str, Any]) -> None:
        """From a subscription callback: queue the message (never blocks; a full queue is recorded)."""
        try:
            self.queue.put_nowait((index, message, time.time()))
        except queue.Full:
            self.stats["dropped"] += 1
            sub = self.subscriptions[index]
            log.error("gateway queue full (%d): a message from %s recorded, not processed", self.queue.maxsize, sub.topic)
            self._record(SENSOR_MESSAGES, {"source": sub.topic, "message": message,
                                           "error": {"field": "", "message": "gateway queue full"}},
                         "printeps/RejectedMessage")

    def idle(self) -> bool:
        return self.queue.empty() and self.queue.unfinished_tasks == 0

    def _work(self) -> None:
        while not self._stop.is_set():
            try:
                index, message, received = self.queue.get(timeout=0.2)
            except queue.Empty:
                continue
            try:
                self.handle(self.subscriptions[index], message, received)
            except Exception:
                log.exception("ingress failed on a message from %s", self.subscriptions[index].topic)
            finally:
                self.queue.task_done()

    def handle(self, sub: RosSubscription, message: dict[str, Any], received: float | None = None) -> dict[str, Any] | None:
        """Check, map and push one message; returns the stream engine's report (None: rejected)."""
        received = received or time.time()
        stamp = stamp_ms(message.get(sub.stamp_field)) or int(round(received * 1000))
        body = message.get(sub.select) if sub.select else message
        try:
            if not isinstance(body, dict):
                raise ReadingError(sub.select or "message", "is not a message")
            if sub.check is not None:
                self.checks[sub.check](body)
            triples = self.mapper.map(body, stamp, _mapping_name(sub))
        except (ReadingError, MappingError) as exc:
            error = exc.to_dict() if isinstance(exc, ReadingError) else {"field": exc.where, "message": exc.message}
            return self._reject(sub, message, error, exc)
        try:
            report = self.streams.push(sub.stream, stamp, triples)
        except StreamError as exc:  # the stream refused it (too many triples, ...): still recorded, with why
            return self._reject(sub, message, {"field": "", "message": str(exc)}, exc)
        self.stats["readings"] += 1
        self._record(SENSOR_MESSAGES, {"source": sub.topic, "type": sub.type, "stamp_ms": stamp, "message": message},
                     sub.type)
        self._record(RDF_EVENTS, {"stream": sub.stream, "stamp_ms": stamp, "source": sub.topic,
                                  "triples": [[str(t) for t in triple] for triple in triples]},
                     "printeps/RdfStreamItem")
        return report

    def _reject(self, sub: RosSubscription, message: dict[str, Any], error: dict[str, Any], exc: Exception) -> None:
        """Count, log, record and announce a message that did not reach the stream."""
        self.stats["rejected"] += 1
        log.error("rejected a message from %s: %s", sub.topic, exc)
        self._record(SENSOR_MESSAGES, {"source": sub.topic, "type": sub.type, "message": message, "error": error},
                     "printeps/RejectedMessage")
        self.on_event("rejected", {"source": sub.topic, "error": str(exc)})
        return None

    def _record(self, collection: str, doc: dict[str, Any], stored_type: str) -> None:
        if self.store is not None:
            self.store.record(collection, doc, stored_type=stored_type, inserted_by=BY)


def _mapping_name(sub: RosSubscription) -> str:
    """A named mapping, else the one the bridge registered for the topic (inline or introspected)."""
    return sub.mapping if isinstance(sub.mapping, str) else topic_mapping(sub.topic)


def topic_mapping(topic: str) -> str:
    return f"topic:{topic}"
