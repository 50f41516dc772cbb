"""Durable stateful sessions: a session is event-sourced, so another process (or this one after a
restart) can rebuild it exactly (issue 28; design note "Durable sessions without KieMarshallers").

Why event-sourced: the Drools jars we ship have no session marshaller, and a session's facts are
plain JSON anyway. So:

- **The log.** Every command batch that changes a session (insert, modify, update, delete, fire,
  advance, set_global, set_focus, clear_*, a KIE batch as one entry) is written, once the engine
  accepted it and before the caller gets the answer, as one entry: its sequence number, the
  commands as the client sent them, the handles its inserts returned and the handles its updates
  left. A refused batch is not journalled; a batch that fails half-way (a then-part throwing, the
  runaway guard, ``engine.fire_timeout_s``) is rolled back by rebuilding the session without it.
  A move to a new version (``follow``) is an entry too.
- **Snapshots.** Every ``sessions.snapshot_every`` entries or ``sessions.snapshot_interval_s``
  seconds, after the command that makes one due (any command), the session's state is written:
  facts in insertion order with every handle text clients may hold for them, clock, globals,
  the agenda-group focus stack (``Session.snapshot`` in Java) and the matches still pending in
  every agenda group (``Session.takePending``, keys naming facts by their place). A restore counts every other match
  over those facts as fired (refraction, as a deploy's move carries it). Taking the pending
  matches consumes them, so the live session is then replaced by one restored from the snapshot
  (:meth:`gateway.engine.session.StatefulSession._snapshot`); right after a full fire of rules
  that name no agenda group nothing is pending, and the state is only read.
- **Rebuild.** A new session on the snapshot's version, the snapshot restored, the entries after it
  replayed (each replayed insert's new handle aliased to the one the client holds). A snapshot that
  cannot be read falls back to the one before it (two are kept, with the log since the older), then
  to the whole log; if none works the rebuild fails naming the session and why, and nothing is half
  built.

This module is the plain-Python part (which commands count, when to snapshot, the replay order);
where the log is kept is a :class:`SessionLog` (``gateway.runtime.session_log`` keeps it in the
Information State through the journal).
"""

from __future__ import annotations

import hashlib
import logging
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol

import orjson

from gateway.engine.errors import EngineError

log = logging.getLogger(__name__)

#: Batch ops that change a session (the others only read it).
CHANGE_OPS = frozenset({"insert", "delete", "modify", "update", "fire", "set_global", "set_focus", "clear_agenda_group",
                        "clear_agenda", "clear_activation_group", "advance", "advance_to", "dispose"})
#: Ops whose handle's text changes with them (an update swaps the object, and its identity hash).
_RETARGET_OPS = frozenset({"modify", "update"})


class RebuildFailed(EngineError):
    """A durable session cannot be rebuilt (every snapshot and the log were tried): ``reasons``
    says why for each; ``status`` is 409 when its versions no longer load, 422 when its data is
    unreadable."""

    kind = "rebuild"

    def __init__(self, ruleset: str, session_id: str, reasons: list[str], status: int = 409) -> None:
        super().__init__(f"session {session_id} of {ruleset} cannot be rebuilt: " + "; ".join(reasons))
        self.ruleset, self.session_id, self.reasons, self.status = ruleset, session_id, reasons, status

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind, "ruleset": self.ruleset, "session": self.session_id,
                "reasons": self.reasons}


class Rebuilding(EngineError):
    """The session is being rebuilt (here, or the Information State must first catch up): retry."""

    kind = "rebuilding"

    def __init__(self, message: str, retry_after_s: int = 1) -> None:
        super().__init__(message)
        self.retry_after_s = retry_after_s

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind, "retry_after_s": self.retry_after_s}


class JournalRefused(EngineError):
    """The command ran but could not be journalled (the journal is full): it was rolled back, and
    the caller may send it again once the journal has drained (``Retry-After``)."""

    kind = "journal"
    retry_after_s = 5


class NotYetShared(EngineError):
    """(``sessions.ack_after: database``) The command is journalled here but did not reach the
    Information State in time: it is kept and will be shipped; the caller must not resend it."""

    kind = "journal"
    retry_after_s = 1


@dataclass
class Snapshot:
    """One stored snapshot: the state after entry ``seq``, on ``version``."""

    seq: int
    version: int
    state: str
    digest: str
    at: float

    def readable(self) -> bool:
        return hashlib.sha256(self.state.encode("utf-8")).hexdigest() == self.digest


@dataclass
class History:
    """What the log holds for one session: its opening, its snapshots (newest first) and its
    entries after the oldest kept snapshot (in order)."""

    opening: dict[str, Any]
    snapshots: list[Snapshot] = field(default_factory=list)
    entries: list[dict[str, Any]] = field(default_factory=list)
    disposed: bool = False

    @property
    def last_seq(self) -> int:
        seqs = [e["seq"] for e in self.entries] + [s.seq for s in self.snapshots]
        return max(seqs, default=0)

    def complete(self) -> bool:
        """Whether the entries run from the first one (the session can be rebuilt from nothing)."""
        return all(e["seq"] == i for i, e in enumerate(self.entries, start=1))


class SessionLog(Protocol):
    """Where durable sessions' entries and snapshots are kept."""

    def append(self, ruleset: str, session_id: str, epoch: str, entry: dict[str, Any]) -> None:
        """Journal ``entry`` of incarnation ``epoch`` of the session (an id can be opened again after a dispose) (durable against a killed process once this returns); raises if refused."""

    def save_snapshot(self, ruleset: str, session_id: str, epoch: str, snapshot: Snapshot) -> None: ...

    def history(self, ruleset: str, session_id: str, gone: str | None = None) -> History | None:
        """Everything kept for the session (None: no durable session by that id), once every
        journalled entry (those of ``gone``, the dead owner process, too) is readable; raises
        :class:`Rebuilding` if not yet."""

    def delete(self, ruleset: str, session_id: str, epoch: str) -> None: ...

    def close(self) -> None: ...

    def wait_shipped(self, timeout_s: float) -> bool:
        """Wait until everything journalled so far is in the shared database; False on timeout."""

    def has_room(self, writes: int = 1) -> bool:
        """Whether the journal takes ``writes`` more now (a batch is refused before it runs when
        not: undoing one after it ran needs a rebuild, which needs the database)."""

    def sessions(self, ruleset: str | None = None) -> list[dict[str, Any]]:
        """The openings of the durable sessions kept (for a restart that looks them up)."""

    def stored(self, ruleset: str, session_id: str) -> bool:
        """Whether a durable session by that id is kept (opened, not disposed); raises
        :class:`Rebuilding` when that cannot be told now (the database is away)."""

    def last_activity(self, opening: dict[str, Any]) -> float:
        """When the session last changed (epoch seconds)."""


def changes(commands: list[dict[str, Any]]) -> bool:
    """Whether a batch changes the session (only those are journalled)."""
    return any(c.get("op") in CHANGE_OPS for c in commands)


def quiescent(commands: list[dict[str, Any]], results: list[dict[str, Any]], fire_limit: int) -> bool:
    """Whether the agenda holds nothing to fire after this batch: its last changing command is a
    full fire (no ``max``) that stopped by itself, before the runaway guard."""
    last = next((i for i in range(len(commands) - 1, -1, -1) if commands[i].get("op") in CHANGE_OPS), None)
    if last is None or commands[last].get("op") != "fire":
        return False
    most = commands[last].get("max")
    if most is not None and int(most) >= 0:  # fire at most n: matches may be left
        return False
    fire = next((r.get("fire") for r in results if r.get("i") == last and "fire" in r), None)
    return fire is not None and int(fire.get("fireCount", fire_limit)) < fire_limit


def batch_entry(seq: int, commands: list[dict[str, Any]], results: list[dict[str, Any]], clock_ms: int | None,
                current: Callable[[str], str | None]) -> dict[str, Any]:
    """The log entry of an accepted batch: the commands, the handles its inserts returned, and
    (through ``current``, the session's handle lookup) the handle text its updates left."""
    inserted = {str(r["i"]): r["handles"] for r in results if r.get("op") == "insert" and r.get("handles")}
    retargeted: dict[str, str] = {}
    for i, command in enumerate(commands):
        if command.get("op") in _RETARGET_OPS and command.get("handle"):
            now = current(str(command["handle"]))
            if now is not None and now != command["handle"]:
                retargeted[str(i)] = now
    entry: dict[str, Any] = {"kind": "batch", "seq": seq, "commands": commands, "time": clock_ms, "at": time.time()}
    if inserted:
        entry["handles"] = inserted
    if retargeted:
        entry["current"] = retargeted
    return entry


class Durability:
    """A durable session's place in its log (used under the session's lock)."""

    def __init__(self, log: SessionLog, ruleset: str, session_id: str, epoch: str, *, every: int, interval_s: float,
                 seq: int = 0, snapshot_seq: int = 0, last_snapshot: float | None = None,
                 shared_within_s: float | None = None) -> None:
        self.log = log
        self.shared_within_s = shared_within_s  # ack_after: database (None: once journalled)
        self.ruleset, self.session_id, self.epoch = ruleset, session_id, epoch
        self.every, self.interval_s = every, interval_s
        self.seq = seq
        self.snapshot_seq = snapshot_seq
        self.last_snapshot = last_snapshot
        self._since = time.monotonic()
        self.snapshot_error: str | None = None

    @property
    def commands_since_snapshot(self) -> int:
        return self.seq - self.snapshot_seq

    def open(self, opening: dict[str, Any]) -> None:
        self.log.append(self.ruleset, self.session_id, self.epoch, {"kind": "open", "seq": 0, "at": time.time(), **opening})

    def check_room(self, commands: list[dict[str, Any]]) -> None:
        """Refuses (:class:`JournalRefused`, nothing run) a changing batch the journal has no room for."""
        if changes(commands) and not self.log.has_room(2):  # the entry, and a snapshot it may make due
            raise JournalRefused(f"session {self.session_id} of {self.ruleset}: the journal is full (store.spool_max_docs "
                                 "writes not yet in the Information State): the command was not run; retry later")

    def record(self, commands: list[dict[str, Any]], results: list[dict[str, Any]], clock_ms: int | None,
               current: Callable[[str], str | None]) -> None:
        """Journals an accepted batch (raises if the journal refuses it: the caller rolls back)."""
        entry = batch_entry(self.seq + 1, commands, results, clock_ms, current)
        self.log.append(self.ruleset, self.session_id, self.epoch, entry)
        self.seq += 1
        if self.shared_within_s is not None and not self.log.wait_shipped(self.shared_within_s):
            raise NotYetShared(f"session {self.session_id} of {self.ruleset}: command {self.seq} is journalled here but "
                               f"not yet in the Information State (sessions.ack_after: database); it is kept and will be "
                               "shipped: do not resend it")

    def record_move(self, old: int, new: int, unchanged: list[str]) -> None:
        self.log.append(self.ruleset, self.session_id, self.epoch,
                        {"kind": "move", "seq": self.seq + 1, "from": old, "to": new, "unchanged": unchanged, "at": time.time()})
        self.seq += 1

    def due(self) -> bool:
        if self.commands_since_snapshot <= 0:
            return False
        if self.commands_since_snapshot >= self.every:
            return True
        return self.interval_s > 0 and time.monotonic() - self._since >= self.interval_s

    def snapshot(self, java: Any, version: int) -> bool:
        """Writes a snapshot of ``java`` (a session with nothing pending in any agenda group, so a
        restore counts every match over its facts as fired); False (and why in
        ``snapshot_error``) if the state cannot be written: the log keeps growing instead."""
        answer = str(java.snapshot())
        if not answer.startswith('{"ok":true'):
            self.refused(str(orjson.loads(answer).get("message")))
            return False
        self.save(answer, version)
        return True

    def refused(self, why: str) -> None:
        """No snapshot now (``why``): the log keeps growing; tried again after the interval."""
        self.snapshot_error = why
        log.warning("session %s of %s: no snapshot: %s", self.session_id, self.ruleset, why)
        self._since = time.monotonic()

    def save(self, state: str, version: int) -> None:
        """Writes ``state`` (``Session.snapshot``'s JSON, with its ``pending`` matches if any were)
        as the snapshot after the current entry."""
        snap = Snapshot(self.seq, version, state, hashlib.sha256(state.encode("utf-8")).hexdigest(), time.time())
        self.log.save_snapshot(self.ruleset, self.session_id, self.epoch, snap)
        self.snapshot_seq, self.last_snapshot, self.snapshot_error = self.seq, snap.at, None
        self._since = time.monotonic()

    def info(self) -> dict[str, Any]:
        out: dict[str, Any] = {"durable": True, "last_snapshot": self.last_snapshot,
                               "commands_since_snapshot": self.commands_since_snapshot}
        if self.snapshot_error:
            out["snapshot_error"] = self.snapshot_error
        return out


# ---------------------------------------------------------------------------------------- rebuild


@dataclass
class Rebuilt:
    """A rebuilt Java session, its version, and where it stands in its log."""

    java: Any
    version: int
    seq: int
    snapshot_seq: int
    last_snapshot: float | None


class Builder(Protocol):
    """What a rebuild needs from the engine."""

    def java_session(self, version: int) -> Any:
        """A fresh Java session of ``version`` of the session's rule set (raises if it no longer loads)."""

    def unchanged_rules(self, old: int, new: int) -> list[str]: ...


def rebuild(history: History, builder: Builder, fire_limit: int, ruleset: str, session_id: str) -> Rebuilt:
    """The session ``history`` describes, from its newest readable snapshot (then older ones, then
    the whole log): :class:`RebuildFailed` naming each attempt's reason if none works."""
    reasons: list[str] = []
    status = 409
    starts: list[Snapshot | None] = list(history.snapshots)
    if history.complete():
        starts.append(None)
    for start in starts:
        try:
            return _rebuild_from(start, history, builder, fire_limit)
        except _Unusable as exc:
            where = f"snapshot after command {start.seq}" if start else "the log from its start"
            reasons.append(f"{where}: {exc}")
            status = 422 if exc.data else status
            log.warning("session %s of %s: %s unusable: %s", session_id, ruleset, where, exc)
    if not starts:
        reasons.append("no snapshot, and the log before the oldest snapshot was dropped")
    raise RebuildFailed(ruleset, session_id, reasons, status)


class _Unusable(Exception):
    def __init__(self, message: str, data: bool = False) -> None:
        super().__init__(message)
        self.data = data  # the stored data is unreadable (else: a version no longer loads or runs it)


def _rebuild_from(start: Snapshot | None, history: History, builder: Builder, fire_limit: int) -> Rebuilt:
    version = start.version if start else int(history.opening["version"])
    if start is not None and not start.readable():
        raise _Unusable("its digest does not match its content (corrupt)", data=True)
    java = _session(builder, version)
    try:
        if start is not None:
            answer = orjson.loads(str(java.restore(start.state)))
            if not answer.get("ok"):
                raise _Unusable(str(answer.get("message")), data="readable" in str(answer.get("message")))
        after = start.seq if start else 0
        for entry in history.entries:
            if entry["seq"] <= after:
                continue
            if entry.get("kind") == "move":
                java, version = _replay_move(java, entry, builder), int(entry["to"])
            else:
                _replay_batch(java, entry, fire_limit)
    except BaseException:
        java.dispose()
        raise
    return Rebuilt(java, version, history.last_seq, start.seq if start else 0, start.at if start else None)


def _session(builder: Builder, version: int) -> Any:
    try:
        return builder.java_session(version)
    except Exception as exc:
        raise _Unusable(f"version {version} does not load: {exc}") from None


def _replay_batch(java: Any, entry: dict[str, Any], fire_limit: int) -> None:
    commands = entry["commands"]
    answer = orjson.loads(str(java.execute(orjson.dumps(commands).decode("utf-8"), fire_limit)))
    if not answer.get("ok"):
        raise _Unusable(f"command {entry['seq']} no longer runs: {answer.get('message')}")
    inserted = entry.get("handles") or {}
    for result in answer.get("results", []):
        if result.get("op") == "insert":
            for held, now in zip(inserted.get(str(result["i"]), []), result.get("handles", [])):
                if held != now:
                    java.alias(held, now)
    for index, held in (entry.get("current") or {}).items():
        now = java.currentHandle(str(commands[int(index)]["handle"]))
        if now is not None and str(now) != held:
            java.alias(held, str(now))


def _replay_move(java: Any, entry: dict[str, Any], builder: Builder) -> Any:
    new = _session(builder, int(entry["to"]))
    answer = orjson.loads(str(new.moveFrom(java, orjson.dumps(sorted(entry.get("unchanged") or [])).decode())))
    if not answer.get("ok"):
        new.dispose()
        raise _Unusable(f"the move to version {entry['to']} no longer fits: {answer.get('message')}")
    java.dispose()
    return new


__all__ = ["CHANGE_OPS", "Builder", "Durability", "History", "JournalRefused", "NotYetShared", "RebuildFailed", "Rebuilding", "Rebuilt",
           "SessionLog", "Snapshot", "batch_entry", "changes", "quiescent", "rebuild"]
