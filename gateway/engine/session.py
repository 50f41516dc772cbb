"""Long-lived stateful sessions: event streams (C-SPARQL results, sensor events), and the
conversations of KIE Server and REST clients (command batches with real fact handles).

A session runs on one rule set version. What happens when a new version is deployed is decided
by :mod:`gateway.engine.sessions` (its deploy policy): by default the session moves to it with its
facts (:meth:`StatefulSession.move_to`, like ``KieContainer.updateToVersion``); a pinned one stays.
Time is a pseudo clock (moved by event timestamps or ``advance``), so replaying recorded data fires
the same rules, or the wall clock for a session opened with ``clock="realtime"``.
"""

from __future__ import annotations

import itertools
import logging
import json
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable

import jpype.nio
import orjson

from gateway.engine import durable
from gateway.engine.errors import EngineError, FactError
from gateway.engine.feed import EventFeed
from gateway.engine.results import BUFFER_BYTES, NO_TIMESTAMP, FireResult, decode_result, encode_facts, encode_facts_bytes

_ids = itertools.count(1)
log = logging.getLogger(__name__)


def _text(value: Any) -> str | None:
    return None if value is None else str(value)


def _check(answer: Any) -> dict[str, Any]:
    data = orjson.loads(str(answer))
    if not data.get("ok"):
        raise FactError(data.get("errors", []), data.get("errorCount"))
    return data


class CommandFailed(EngineError):
    """A command batch was refused or stopped: which command (``index``, ``op``), what kind of
    problem (``facts``, ``handle``, ``globals``, ``query``, ``clock``, ``runtime``, ``runaway``…),
    the field, and whether earlier commands had already been applied (``applied``: only for
    failures while executing — a batch that fails its checks changes nothing)."""

    def __init__(self, index: int, op: str | None, kind: str, field: str | None, message: str, applied: bool = False,
                 results: list[dict[str, Any]] | None = None) -> None:
        where = f"command {index}" + (f" ({op})" if op else "") if index >= 0 else "the batch"
        super().__init__(f"{where}: {message}")
        self.index, self.op, self.kind, self.field, self.detail = index, op, kind, field, message
        self.applied = applied
        self.results = results or []
        self.rolled_back = False  # a durable session was rebuilt without the batch (see StatefulSession._roll_back)

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": "command", "index": self.index, "op": self.op, "problem": self.kind,
                "field": self.field, "message": self.detail, "applied": self.applied}


@dataclass
class BatchAnswer:
    """What a batch of commands produced: per command ``{"i", "op", "out"?, "value"?, "handles"?,
    "fire"?}`` (objects at their end-of-batch state), the session's clock and fact count after it,
    and whether it disposed the session."""

    results: list[dict[str, Any]]
    time: int | None
    fact_count: int | None
    disposed: bool
    version: int
    duration_ms: float

    @property
    def fires(self) -> list[dict[str, Any]]:
        return [r["fire"] for r in self.results if "fire" in r]

    def actions(self) -> list[dict[str, Any]]:
        return [a for f in self.fires for a in f.get("actions", [])]

    def fired(self) -> list[dict[str, Any]]:
        return [x for f in self.fires for x in f.get("fired", [])]


class StatefulSession:
    """A Drools KieSession kept between calls (thread-safe: one call at a time, under its lock).

    ``id`` is unique within its rule set: a declared ksession's name (``defaultKieSession``) or a
    generated one. ``kind`` says who opened it (``kie``/``rest``: a conversation; ``stream``: a
    stream binding). ``on_deploy`` is ``follow`` (move to a new version with the facts) or ``pin``.
    """

    def __init__(
        self,
        java_session: Any,
        ruleset: str,
        version: int,
        fire_limit: int,
        max_facts: int,
        on_close: Callable[[str], None] | None = None,
        *,
        session_id: str | None = None,
        clock: str = "pseudo",
        on_deploy: str = "follow",
        kind: str = "stream",
        record_facts: bool = True,
    ):
        self.id = session_id or f"s{next(_ids)}"
        self.ruleset = ruleset
        self.version = version
        self.clock = clock
        self.on_deploy = on_deploy
        self.kind = kind
        self.record_facts = record_facts
        self.created_at = time.time()
        self.last_used = time.monotonic()
        self.moves: list[dict[str, Any]] = []  # versions it moved to (or stayed on), newest last
        self.pinned_reason: str | None = None  # why it did not follow a deploy
        self.fact_limit: int | None = None  # facts the session may hold (conversations: sessions.max_facts)
        self._java = java_session
        self._fire_limit = fire_limit
        self._max_facts = max_facts
        self.closed = False
        self._on_close = on_close
        self._feeds: list[Any] = []  # EventFeeds into this session, stopped when it closes
        # A durable session's place in its log (see gateway.engine.durable), and how to rebuild it
        # from that log (to roll back a batch that failed half-way); None: it dies with its process.
        self.durability: durable.Durability | None = None
        self.rebuilder: Callable[[], durable.Rebuilt] | None = None
        # One call at a time, and none while the session moves to a new version.
        self._lock = threading.RLock()
        # push() shares these with the Java session (see Session.attachBuffers): the facts go in
        # and the answer comes out as UTF-8 bytes, and the call itself carries only numbers.
        self._push_lock = self._lock
        self._in = bytearray(BUFFER_BYTES)
        self._out = bytearray(BUFFER_BYTES)
        self._in_view = memoryview(self._in)
        self._attach(java_session)

    def _attach(self, java_session: Any) -> None:
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

    def _call(self, method: str, *args: Any) -> Any:
        """One call into the Java session, under the lock (a move to a new version swaps it)."""
        with self._lock:
            self.last_used = time.monotonic()
            return getattr(self._live(), method)(*args)

    def insert(self, facts: list[dict[str, Any]]) -> int:
        """Inserts facts; facts with an ``id`` can later be updated/retracted by it."""
        data = _check(self._call("insert", encode_facts(facts, self._max_facts)))
        return int(data["inserted"])

    def insert_event(self, fact: dict[str, Any], timestamp_ms: int) -> None:
        """Inserts one event stamped with its time; the session clock moves forward to it."""
        _check(self._call("insertAt", encode_facts([fact], self._max_facts), int(timestamp_ms)))

    def push(self, facts: list[dict[str, Any]], timestamp_ms: int | None = None, return_facts: bool = False) -> FireResult:
        """Inserts ``facts`` (stamped with ``timestamp_ms`` if given) and fires, in one JVM call.

        The stream path: each event (or small batch) is answered with the actions it caused. Facts
        and answer travel through the session's shared buffers, so the one JPype crossing converts
        no strings (a push costs ~2x the bare Drools insert + fire; see bench/engine_bench_notes.md).
        """
        started = time.perf_counter()
        stamp = NO_TIMESTAMP if timestamp_ms is None else int(timestamp_ms)
        data = encode_facts_bytes(facts, self._max_facts)
        size = len(data)
        if size > BUFFER_BYTES:
            answer = str(self._call("pushAt", data.decode("utf-8"), stamp, self._fire_limit, return_facts))
            return decode_result(answer, self.ruleset, self.version, (time.perf_counter() - started) * 1000)
        with self._push_lock:  # the buffers are the session's: one push at a time uses them
            java = self._live()
            self.last_used = time.monotonic()
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
        _check(self._call("update", json.dumps(fact, allow_nan=False)))

    def retract(self, fact_id: str) -> None:
        _check(self._call("retract", str(fact_id)))

    def query(self, name: str, arguments: list[Any] | None = None) -> dict[str, Any]:
        """Runs the rule set's DRL ``query name(...)``: ``{"identifiers": [...], "rows": [{id: value}]}``."""
        data = _check(self._call("query", str(name), json.dumps(list(arguments or []), allow_nan=False)))
        return {"identifiers": data["identifiers"], "rows": data["rows"]}

    def set_global(self, name: str, value: Any) -> None:
        """Sets a global the rule set declares (``global java.util.List seats;``), strictly typed."""
        _check(self._call("setGlobal", str(name), json.dumps(value, allow_nan=False)))

    def get_global(self, name: str) -> Any:
        return _check(self._call("getGlobal", str(name)))["value"]

    def advance_clock(self, ms: int) -> int:
        return int(self._call("advanceBy", int(ms)))

    def advance_to(self, timestamp_ms: int) -> int:
        return int(self._call("advanceTo", int(timestamp_ms)))

    @property
    def clock_ms(self) -> int:
        return int(self._call("now"))

    @property
    def fact_count(self) -> int:
        return int(self._call("factCount"))

    def fire(self, return_facts: bool = False) -> FireResult:
        """Fires what is activated; returns the actions and firings since the last fire."""
        started = time.perf_counter()
        answer = str(self._call("fire", self._fire_limit, return_facts))
        return decode_result(answer, self.ruleset, self.version, (time.perf_counter() - started) * 1000)

    def insert_and_fire_count(self, facts_json: str) -> int:
        """Throughput path: a pre-encoded batch in, the number of firings out."""
        return int(self._call("insertAndFireCount", facts_json, self._fire_limit))

    # ------------------------------------------------------------------ command batches

    def execute(self, commands: list[dict[str, Any]]) -> BatchAnswer:
        """Runs a batch of commands (see ``java/…/Batch.java`` for the list) under the session's
        lock: checked first (nothing changes if any is refused), then executed in order.
        Raises :class:`CommandFailed` naming the command."""
        payload = orjson.dumps(commands).decode("utf-8")
        started = time.perf_counter()
        with self._lock:
            java = self._live()
            self.last_used = time.monotonic()
            self._check_fact_limit(java, commands)
            if self.durability is not None:
                self.durability.check_room(commands)
            answer = orjson.loads(str(java.execute(payload, self._fire_limit)))
            version = self.version
            rolled_back = False
            if self.durability is not None and not answer.get("disposed"):
                if answer.get("ok"):
                    self._journal(commands, answer)
                elif "results" in answer:  # stopped while executing: back to the state before the batch
                    rolled_back = self._roll_back(str(answer.get("message")))
        if answer.get("disposed"):
            self._closed_by_batch()
        if not answer.get("ok"):
            failed = CommandFailed(int(answer.get("index", -1)), answer.get("op"), str(answer.get("kind")), answer.get("field"),
                                   str(answer.get("message")), bool(answer.get("applied")) and not rolled_back,
                                   answer.get("results"))
            failed.rolled_back = rolled_back
            raise failed
        return BatchAnswer(answer["results"], answer.get("time"), answer.get("factCount"), bool(answer.get("disposed")),
                           version, (time.perf_counter() - started) * 1000)

    def _journal(self, commands: list[dict[str, Any]], answer: dict[str, Any]) -> None:
        """(Under the lock) Journals an accepted batch of a durable session before it is answered,
        and snapshots the session when one is due and nothing is left to fire. A batch the journal
        refuses is rolled back and refused (:class:`durable.JournalRefused`)."""
        state = self.durability
        assert state is not None
        if not durable.changes(commands):
            return
        java = self._java
        try:
            state.record(commands, answer["results"], answer.get("time"), lambda text: _text(java.currentHandle(text)))
        except durable.NotYetShared:
            raise  # journalled and applied: not undone
        except Exception as exc:
            undone = self._roll_back(f"not journalled: {exc}")
            raise durable.JournalRefused(f"session {self.id} of {self.ruleset}: the command was not kept ({exc}) and "
                                         + ("was undone; retry later" if undone else
                                            "could not be undone (the Information State is away): the session holds it "
                                            "until its process ends")) from None
        if state.due():
            try:
                self._snapshot(durable.quiescent(commands, answer["results"], self._fire_limit))
            except Exception:  # the log keeps everything meanwhile: a rebuild replays more
                log.warning("session %s of %s: snapshot failed", self.id, self.ruleset, exc_info=True)

    def _snapshot(self, quiet: bool) -> None:
        """(Under the lock) Writes a snapshot at this command boundary. Right after a full fire of
        rules that name no agenda group nothing is pending: the state is only read. Otherwise the
        snapshot carries the pending matches of every agenda group; taking them consumes them, so
        the state is first restored into a fresh session (a state that does not fit changes
        nothing), the pending matches taken, and the fresh session, which fires exactly what this
        one would have (see Carry.java), replaces this one."""
        state, java = self.durability, self._java
        assert state is not None
        if quiet and not bool(java.hasAgendaGroups()):
            state.snapshot(java, self.version)
            return
        text = str(java.snapshot())
        if not text.startswith('{"ok":true'):
            state.refused(str(orjson.loads(text).get("message")))
            return
        fresh = java.twin()
        restored = orjson.loads(str(fresh.restoreFacts(text)))
        if not restored.get("ok"):
            fresh.dispose()
            state.refused(f"its state does not restore: {restored.get('message')}")
            return
        pending = str(java.takePending())
        fresh.refract(pending)
        self._java = fresh
        self._attach(fresh)
        java.dispose()
        state.save(text[:-1] + ',"pending":' + pending + "}", self.version)

    def _roll_back(self, why: str) -> bool:
        """(Under the lock) Rebuilds the session from its log, without the batch that just failed
        half-way; True if it did. A session that cannot be rebuilt keeps its state as it is."""
        if self.rebuilder is None:
            return False
        try:
            rebuilt = self.rebuilder()
        except Exception:
            log.exception("session %s of %s: could not roll back (%s); it keeps the half-applied batch",
                          self.id, self.ruleset, why)
            return False
        old = self._java
        self._install(rebuilt)
        old.dispose()
        log.info("session %s of %s rolled back to command %d (%s)", self.id, self.ruleset, rebuilt.seq, why)
        return True

    def _install(self, rebuilt: durable.Rebuilt) -> None:
        """(Under the lock) Takes ``rebuilt`` as this session's Java session and log position."""
        self._java = rebuilt.java
        self._attach(rebuilt.java)
        self.version = rebuilt.version
        if self.durability is not None:
            self.durability.seq = rebuilt.seq
            self.durability.snapshot_seq = rebuilt.snapshot_seq
            self.durability.last_snapshot = rebuilt.last_snapshot

    def _check_fact_limit(self, java: Any, commands: list[dict[str, Any]]) -> None:
        if self.fact_limit is None:
            return
        inserts = [(i, len(c.get("facts") or ())) for i, c in enumerate(commands) if c.get("op") == "insert"]
        adding = sum(n for _, n in inserts)
        if not adding:
            return
        held = int(java.factCount())
        if held + adding > self.fact_limit:
            raise CommandFailed(inserts[0][0], "insert", "limit", "object",
                                f"the session holds {held} facts; {adding} more would pass its limit of "
                                f"{self.fact_limit} (sessions.max_facts): retract some or open another session")

    def _closed_by_batch(self) -> None:
        """A ``dispose`` command ended the Drools session: finish closing it here."""
        if not self.closed:
            for feed in self._feeds:
                feed.abort()
            self.closed = True
            if self._on_close is not None:
                self._on_close(self.id)

    # ------------------------------------------------------------------ moving to a new version

    def move_to(self, compiled: Any, version: int, unchanged_rules: list[str], new_java: Any) -> bool:
        """Moves the session's state (facts, handles, clock, globals, focus) into ``new_java``, a
        fresh Java session of ``version``; True if it moved. A fact that does not fit the new
        version (type or field gone, value no longer allowed) keeps the session on its version
        (``pinned_reason`` says why) and changes nothing."""
        with self._lock:
            if self.closed or self.version == version:  # gone, or moved there already (another thread)
                new_java.dispose()
                return not self.closed
            if any(not f.closed for f in self._feeds):
                new_java.dispose()
                self._stay(version, "an event feed is open on it")
                return False
            answer = orjson.loads(str(new_java.moveFrom(self._java, orjson.dumps(sorted(unchanged_rules)).decode())))
            if not answer.get("ok"):
                new_java.dispose()
                self._stay(version, str(answer.get("message")))
                return False
            if self.durability is not None:
                try:
                    self.durability.record_move(self.version, version, sorted(unchanged_rules))
                except Exception as exc:  # not journalled: a rebuild could not follow it, so it does not move
                    new_java.dispose()
                    self._stay(version, f"the move could not be journalled: {exc}")
                    return False
            old, old_version = self._java, self.version
            self._java = new_java
            self._attach(new_java)
            self.version = version
            self.pinned_reason = None
            self.moves.append({"from": old_version, "to": version, "facts": int(answer.get("facts", 0)), "at": time.time()})
            del self.moves[:-20]
        old.dispose()
        return True

    def _stay(self, version: int, reason: str) -> None:
        self.pinned_reason = f"stays on version {self.version} (version {version} was deployed): {reason}"
        self.moves.append({"from": self.version, "to": self.version, "refused": version, "reason": reason, "at": time.time()})
        del self.moves[:-20]

    def close(self) -> None:
        """Disposes the Drools session and forgets it in the engine."""
        with self._lock:
            if self.closed:
                return
            for feed in self._feeds:
                feed.abort()
            self.closed = True
            self._java.dispose()
        if self._on_close is not None:
            self._on_close(self.id)

    @property
    def idle_s(self) -> float:
        return time.monotonic() - self.last_used

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"id": self.id, "ruleset": self.ruleset, "version": self.version, "kind": self.kind,
                               "clock": self.clock, "on_deploy": self.on_deploy, "closed": self.closed,
                               "created_at": self.created_at, "idle_s": round(self.idle_s, 3)}
        if not self.closed:
            try:
                with self._lock:
                    out["time"] = int(self._java.now())
                    out["fact_count"] = int(self._java.factCount())
            except Exception:  # disposed under us: the fields are simply left out
                pass
        out.update(self.durability.info() if self.durability is not None else {"durable": False})
        if self.pinned_reason:
            out["pinned_reason"] = self.pinned_reason
        if self.moves:
            out["moves"] = list(self.moves)
        return out
