"""Pipelined event feeds: one event per call into a stateful session, answers delivered in order.

Why: :meth:`StatefulSession.push` answers an event before it returns, so the caller's thread does
the Python work (encode, decode, react) and the Drools work one after the other, and crosses into
the JVM once per event. With an :class:`EventFeed`, ``submit`` hands the event over and returns;
the session's Java worker inserts and fires each event on its own (the same rule semantics as
``push``), while the caller already prepares the next ones. Python and Drools then run on two
cores at once (see docs/engine-api.md and docs/benchmarks.md).

Crossings are gathered the way Nagle's algorithm gathers packets: an event crosses at once when
nothing is in flight (lowest latency for a sparse stream); under load, events submitted while
earlier ones are being fired cross together (at most ``GATHER`` at a time), and their answers are
collected together. Like a Kafka producer's delivery callbacks, answers are handed to
``on_result`` by ``submit`` and ``flush`` in the caller's thread; answers nobody collected within
``linger_ms`` (the stream paused) are handed over by the feed's own thread.
"""

from __future__ import annotations

import collections
import logging
import struct
import threading
import time
from typing import Any, Callable

import jpype.nio
import orjson

from gateway.base import jvm
from gateway.engine.errors import EngineError
from gateway.engine.results import BUFFER_BYTES, NO_TIMESTAMP, FireResult, encode_facts_bytes, raise_refusal

log = logging.getLogger(__name__)

_NONE, _OVERFLOW, _FINISHED = 0, -1, -2  # Feed.poll's answers besides a length
# At most this many events are gathered before they cross: the crossing also lets the delivery
# thread take the GIL, so answers flow back while the caller keeps submitting.
GATHER = 64
_HEADER = struct.Struct("<iq")  # per event in the input buffer: byte length, timestamp (Feed.submitBatch)


def _log_error(exc: Exception) -> None:
    log.warning("event feed: an event was refused or its rules failed: %s", exc)


class EventFeed:
    """Submit events one at a time; each gets its own insert + fire and its own answer, in order.

    ``on_result(result)`` gets every event's :class:`FireResult` (``duration_ms`` = submit to
    delivery); ``on_error(exc)`` gets the :class:`~gateway.engine.errors.EngineError` of an event
    that was refused (a type or field problem) or whose rules failed or ran away. They are called
    in submission order, never two at once, from ``submit``/``flush`` in the caller's thread or from
    the feed's thread when answers waited ``linger_ms``. ``capacity`` bounds the events in flight:
    ``submit`` collects answers (and waits for them) when the rules fall that far behind.
    """

    def __init__(
        self,
        session: Any,  # StatefulSession (not imported: session.py imports this module)
        on_result: Callable[[FireResult], None],
        on_error: Callable[[Exception], None] | None = None,
        capacity: int = 4096,
        return_facts: bool = False,
        linger_ms: float = 1.0,
    ):
        if capacity < 1:
            raise ValueError("capacity must be at least 1")
        self.session = session
        self._on_result = on_result
        self._on_error = on_error or _log_error
        self._max_facts = session.max_facts
        self._capacity = capacity
        self._linger_us = max(0, int(linger_ms * 1000))
        self._in = bytearray(BUFFER_BYTES)
        self._in_view = memoryview(self._in)
        self._out = bytearray(BUFFER_BYTES)
        self._java = jvm.helper_class("Feed")(
            session.java, session.fire_limit, return_facts,
            jpype.nio.convertToDirectBuffer(self._in), jpype.nio.convertToDirectBuffer(self._out),
        )
        self._lock = threading.Lock()  # the input buffer and the send counters
        self._buffered = 0  # events gathered in the input buffer, not yet handed to Java
        self._buffered_bytes = 0
        self._sent = 0
        self._deliver_lock = threading.Lock()  # one deliverer at a time keeps the answers in order
        self._delivering: threading.Thread | None = None
        self._delivered_cond = threading.Condition()
        self._submitted_at: collections.deque[float] = collections.deque()
        self.submitted = 0
        self.delivered = 0
        self.errors = 0
        self.closed = False
        self._aborted = False
        self._finished = False
        self._thread = threading.Thread(target=self._deliver_lingering, name=f"feed-{session.id}", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ submitting

    def submit(self, facts: list[dict[str, Any]], timestamp_ms: int | None = None) -> None:
        """Queues ``facts`` (one event, or a few facts that belong together) stamped with
        ``timestamp_ms``. JSON problems are refused here; type and field problems come back
        through ``on_error``."""
        data = encode_facts_bytes(facts, self._max_facts)
        stamp = NO_TIMESTAMP if timestamp_ms is None else int(timestamp_ms)
        size = len(data)
        while self.submitted - self.delivered >= self._capacity and not self._finished:
            if self._delivering is threading.current_thread():
                break  # a callback submitting while it is being delivered: let it through
            self._send_buffered()
            if not self._deliver(timeout_ms=50):
                with self._delivered_cond:  # another thread is handing answers over
                    self._delivered_cond.wait(0.005)
        with self._lock:
            if self.closed:
                raise EngineError(f"the event feed of session {self.session.id} is closed")
            self._submitted_at.append(time.perf_counter())
            self.submitted += 1
            if _HEADER.size + size > BUFFER_BYTES:  # too big to gather: what waits first, then it alone
                self._send_locked()
                self._sent += 1
                self._java.submitText(data.decode("utf-8"), stamp)
                return
            if self._buffered_bytes + _HEADER.size + size > BUFFER_BYTES:
                self._send_locked()
            pos = self._buffered_bytes
            _HEADER.pack_into(self._in, pos, size, stamp)
            self._in_view[pos + _HEADER.size : pos + _HEADER.size + size] = data
            self._buffered_bytes = pos + _HEADER.size + size
            self._buffered += 1
            ready = 0
            if self._sent == self.delivered or self._buffered >= GATHER:  # nothing in flight, or enough
                ready = self._send_locked()
        if ready:
            self._deliver(timeout_ms=0)

    def _send_locked(self) -> int:
        """Hands the gathered events to Java; returns how many answers wait to be collected."""
        if not self._buffered:
            return 0
        if self._aborted:  # the session closed: they will never fire (flush reports them)
            self._buffered = self._buffered_bytes = 0
            return 0
        count = self._buffered
        self._buffered = self._buffered_bytes = 0
        self._sent += count
        return int(self._java.submitBatch(count))

    def _send_buffered(self) -> None:
        with self._lock:
            self._send_locked()

    def flush(self, timeout: float | None = None) -> bool:
        """Hands over every answer to the events submitted so far (in this thread); False if
        ``timeout`` (seconds) ran out first."""
        target = self.submitted
        deadline = None if timeout is None else time.monotonic() + timeout
        self._send_buffered()
        while self.delivered < target and not self._finished:
            left_ms = 200 if deadline is None else int((deadline - time.monotonic()) * 1000)
            if left_ms <= 0:
                return False
            if self._delivering is threading.current_thread():
                return False  # flush from inside a callback cannot wait for itself
            if not self._deliver(timeout_ms=min(left_ms, 200)):
                with self._delivered_cond:  # another thread is delivering: wait for its progress
                    self._delivered_cond.wait(0.05)
        if self._aborted and self.delivered < target:
            raise EngineError(f"session {self.session.id} was closed: {target - self.delivered} submitted "
                              "events were dropped before they fired")
        return self.delivered >= target

    @property
    def backlog(self) -> int:
        """Events submitted and not yet delivered."""
        return self.submitted - self.delivered

    def close(self, timeout: float | None = 10.0) -> None:
        """Delivers the answers to everything submitted, then stops the worker and the feed's thread."""
        with self._lock:
            if self.closed:
                return
            self.closed = True
        if self._delivering is threading.current_thread():  # closing from a callback: cannot wait for
            self._send_buffered()                             # the deliveries it is part of
            self._java.close()
            return
        self.flush(timeout)
        self._java.close()
        if threading.current_thread() is not self._thread:
            self._thread.join(timeout)

    def abort(self) -> None:
        """Stops after the event being fired (used when the session closes under the feed): events
        not yet fired are dropped, answers already written are still delivered."""
        with self._lock:
            self.closed = True
            self._aborted = True
            self._buffered = self._buffered_bytes = 0
        self._java.abort()

    # ------------------------------------------------------------------ delivering

    def _deliver(self, timeout_ms: int) -> bool:
        """Collects the waiting answers (waiting up to ``timeout_ms`` for one) and hands them over.
        False if none came or another thread is delivering."""
        if self._delivering is threading.current_thread():
            return False  # a callback submitting: its caller hands over the rest, in order
        if not self._deliver_lock.acquire(blocking=False):
            return False
        try:
            self._delivering = threading.current_thread()
            length = self._java.poll(timeout_ms)
            if length == _FINISHED:
                self._finished = True
                return False
            if length == _NONE:
                return False
            raw = self._out[:length] if length > 0 else str(self._java.takeOverflow())
            self._send_buffered()  # gathered while these were in flight: the worker goes on with them
            answers = orjson.loads(raw)
            for answer in answers:
                self._hand_over(answer)
            self.delivered += len(answers)
        finally:
            self._delivering = None
            self._deliver_lock.release()
        self._send_buffered()  # gathered by a submit that still counted those answers in flight
        with self._delivered_cond:
            self._delivered_cond.notify_all()
        return True

    def _deliver_lingering(self) -> None:
        """The feed's thread: hands over answers nobody collected within the linger time."""
        while not self._finished:
            try:
                if self._java.awaitLingering(self._linger_us, 500) and not self._deliver(timeout_ms=0) \
                        and not self._finished:
                    with self._delivered_cond:  # another thread is handing answers over: let it
                        self._delivered_cond.wait(0.005)
            except Exception:  # the JVM is shutting down, or the session went away
                log.debug("event feed thread stopped", exc_info=True)
                break
        with self._delivered_cond:
            self._delivered_cond.notify_all()

    def _hand_over(self, answer: dict[str, Any]) -> None:
        waited_ms = (time.perf_counter() - self._submitted_at.popleft()) * 1000
        session = self.session
        try:
            if answer.get("ok") is not True:
                raise_refusal(answer)
            result = FireResult(session.ruleset, session.version, answer["actions"], answer["fired"],
                                answer.get("facts", []), answer["fireCount"], waited_ms)
        except EngineError as exc:
            self.errors += 1
            self._call(self._on_error, exc)
            return
        self._call(self._on_result, result)

    @staticmethod
    def _call(callback: Callable[[Any], None], value: Any) -> None:
        try:
            callback(value)
        except Exception:  # a failing callback must not stop the deliveries after it
            log.exception("event feed callback %r failed", callback)
