"""Long-lived stateful sessions, for event streams (C-SPARQL results, sensor events).

A session is bound to the rule set version that was live when it was opened: a hot deploy does
not change the rules under a running stream (open a new session to move on). Time is a pseudo
clock driven by event timestamps, so replaying recorded data fires the same rules.
"""

from __future__ import annotations

import itertools
import json
import threading
import time
from typing import Any, Callable

import jpype.nio
import orjson

from gateway.engine.errors import EngineError, FactError
from gateway.engine.feed import EventFeed
from gateway.engine.results import BUFFER_BYTES, NO_TIMESTAMP, FireResult, decode_result, encode_facts, encode_facts_bytes

_ids = itertools.count(1)


def _check(answer: Any) -> dict[str, Any]:
    data = orjson.loads(str(answer))
    if not data.get("ok"):
        raise FactError(data.get("errors", []), data.get("errorCount"))
    return data


class StatefulSession:
    """A Drools KieSession kept between calls (thread-safe: the Java side synchronizes)."""

    def __init__(
        self,
        java_session: Any,
        ruleset: str,
        version: int,
        fire_limit: int,
        max_facts: int,
        on_close: Callable[[str], None] | None = None,
    ):
        self.id = f"s{next(_ids)}"
        self.ruleset = ruleset
        self.version = version
        self._java = java_session
        self._fire_limit = fire_limit
        self._max_facts = max_facts
        self.closed = False
        self._on_close = on_close
        self._feeds: list[Any] = []  # EventFeeds into this session, stopped when it closes
        # push() shares these with the Java session (see Session.attachBuffers): the facts go in
        # and the answer comes out as UTF-8 bytes, and the call itself carries only numbers.
        self._push_lock = threading.Lock()
        self._in = bytearray(BUFFER_BYTES)
        self._out = bytearray(BUFFER_BYTES)
        self._in_view = memoryview(self._in)
        java_session.attachBuffers(jpype.nio.convertToDirectBuffer(self._in), jpype.nio.convertToDirectBuffer(self._out))

    @property
    def java(self) -> Any:
        """The Java ``Session`` (for the engine's own adapters, such as :class:`EventFeed`)."""
        return self._live()

    @property
    def max_facts(self) -> int:
        return self._max_facts

    @property
    def fire_limit(self) -> int:
        return self._fire_limit

    def _live(self) -> Any:
        if self.closed:
            raise EngineError(f"session {self.id} is closed")
        return self._java

    def insert(self, facts: list[dict[str, Any]]) -> int:
        """Inserts facts; facts with an ``id`` can later be updated/retracted by it."""
        data = _check(self._live().insert(encode_facts(facts, self._max_facts)))
        return int(data["inserted"])

    def insert_event(self, fact: dict[str, Any], timestamp_ms: int) -> None:
        """Inserts one event stamped with its time; the session clock moves forward to it."""
        _check(self._live().insertAt(encode_facts([fact], self._max_facts), int(timestamp_ms)))

    def insert_events(self, facts: list[dict[str, Any]], timestamp_ms: int) -> int:
        data = _check(self._live().insertAt(encode_facts(facts, self._max_facts), int(timestamp_ms)))
        return int(data["inserted"])

    def push(self, facts: list[dict[str, Any]], timestamp_ms: int | None = None, return_facts: bool = False) -> FireResult:
        """Inserts ``facts`` (stamped with ``timestamp_ms`` if given) and fires, in one JVM call.

        The stream path: each event (or small batch) is answered with the actions it caused. Facts
        and answer travel through the session's shared buffers, so the one JPype crossing converts
        no strings (a push costs ~2x the bare Drools insert + fire; see bench/engine_bench_notes.md).
        """
        started = time.perf_counter()
        stamp = NO_TIMESTAMP if timestamp_ms is None else int(timestamp_ms)
        data = encode_facts_bytes(facts, self._max_facts)
        java = self._live()
        size = len(data)
        if size > BUFFER_BYTES:
            answer = str(java.pushAt(data.decode("utf-8"), stamp, self._fire_limit, return_facts))
            return decode_result(answer, self.ruleset, self.version, (time.perf_counter() - started) * 1000)
        with self._push_lock:  # the buffers are the session's: one push at a time uses them
            self._in_view[:size] = data
            length = java.pushBuffered(size, stamp, self._fire_limit, return_facts)
            answer = self._out[:length] if length >= 0 else str(java.takeOverflow())
            return decode_result(answer, self.ruleset, self.version, (time.perf_counter() - started) * 1000)

    def feed(
        self,
        on_result: Callable[[FireResult], None],
        on_error: Callable[[Exception], None] | None = None,
        capacity: int = 4096,
        return_facts: bool = False,
        linger_ms: float = 1.0,
    ) -> "EventFeed":
        """A pipelined feed into this session: ``submit`` one event at a time without waiting for
        its answer; answers reach ``on_result`` in order (see :class:`EventFeed`)."""
        feed = EventFeed(self, on_result, on_error, capacity, return_facts, linger_ms)
        self._feeds = [f for f in self._feeds if not f.closed] + [feed]
        return feed

    def update(self, fact: dict[str, Any]) -> None:
        _check(self._live().update(json.dumps(fact, allow_nan=False)))

    def retract(self, fact_id: str) -> None:
        _check(self._live().retract(str(fact_id)))

    def query(self, name: str, arguments: list[Any] | None = None) -> dict[str, Any]:
        """Runs the rule set's DRL ``query name(...)``: ``{"identifiers": [...], "rows": [{id: value}]}``."""
        data = _check(self._live().query(str(name), json.dumps(list(arguments or []), allow_nan=False)))
        return {"identifiers": data["identifiers"], "rows": data["rows"]}

    def set_global(self, name: str, value: Any) -> None:
        """Sets a global the rule set declares (``global java.util.List seats;``), strictly typed."""
        _check(self._live().setGlobal(str(name), json.dumps(value, allow_nan=False)))

    def get_global(self, name: str) -> Any:
        return _check(self._live().getGlobal(str(name)))["value"]

    def advance_clock(self, ms: int) -> int:
        return int(self._live().advanceBy(int(ms)))

    def advance_to(self, timestamp_ms: int) -> int:
        return int(self._live().advanceTo(int(timestamp_ms)))

    @property
    def clock_ms(self) -> int:
        return int(self._live().now())

    @property
    def fact_count(self) -> int:
        return int(self._live().factCount())

    def fire(self, return_facts: bool = False) -> FireResult:
        """Fires what is activated; returns the actions and firings since the last fire."""
        started = time.perf_counter()
        answer = str(self._live().fire(self._fire_limit, return_facts))
        return decode_result(answer, self.ruleset, self.version, (time.perf_counter() - started) * 1000)

    def insert_and_fire_count(self, facts_json: str) -> int:
        """Throughput path: a pre-encoded batch in, the number of firings out."""
        return int(self._live().insertAndFireCount(facts_json, self._fire_limit))

    def close(self) -> None:
        """Disposes the Drools session and forgets it in the engine."""
        if not self.closed:
            for feed in self._feeds:
                feed.abort()
            self.closed = True
            self._java.dispose()
            if self._on_close is not None:
                self._on_close(self.id)

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "ruleset": self.ruleset, "version": self.version, "closed": self.closed}
