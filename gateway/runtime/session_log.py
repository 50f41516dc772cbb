"""Durable sessions' logs and snapshots in the Information State (``session_log``,
``session_snapshots``), written through the same local journal as decisions.

Why the journal: an entry must be kept before its command is acknowledged, and the journal's
append (a ``write()`` into the page cache) survives a killed process at no database round trip; the
shipper then brings it to MongoDB, where any process of the cluster reads it. A rebuild first has
this process's journal shipped and adopts the segments a dead process on the same data dir left
(:meth:`Journal.catch_up`), so every acknowledged entry is read. On another host, entries the dead
process had not yet shipped are on its disk: see docs/operations.md ("Durable sessions").

Documents: ``{_id: "<ruleset>/<session>/<seq>", key: "<ruleset>/<session>", seq, kind, …}``:
``kind`` is ``open`` (seq 0: version, clock, policy, kind of session), ``batch``, ``move`` or
``disposed``; a snapshot is ``{_id: "<key>/s<seq>", key, seq, version, state, digest, at}``. Two
snapshots are kept, with the entries since the older one; a disposed session's documents are
deleted (off the caller's thread, once the journal has shipped them).
"""

from __future__ import annotations

import logging
import queue
import socket
import threading
import time
from typing import Any

import pymongo
from pymongo.errors import PyMongoError

from gateway.engine.durable import History, Rebuilding, Snapshot

log = logging.getLogger(__name__)

LOG = "session_log"
SNAPSHOTS = "session_snapshots"
KEEP_SNAPSHOTS = 2


def _key(ruleset: str, session_id: str, epoch: str) -> str:
    return f"{ruleset}/{session_id}/{epoch}"


class StoredSessionLog:
    """The :class:`gateway.engine.durable.SessionLog` of one Information State."""

    def __init__(self, store: Any, catch_up_s: float = 30.0) -> None:
        self.store = store  # gateway.store.store.InformationState
        self.catch_up_s = catch_up_s
        self._indexed = False
        self._deletions: queue.Queue[tuple[str, str] | None] = queue.Queue(maxsize=10_000)
        self._deleter = threading.Thread(target=self._delete_loop, name="session-log-cleanup", daemon=True)
        self._deleter.start()
        store.keeps_own_indexes(LOG)
        store.keeps_own_indexes(SNAPSHOTS)

    # ---- writing ------------------------------------------------------------------------------
    def append(self, ruleset: str, session_id: str, epoch: str, entry: dict[str, Any]) -> None:
        key = _key(ruleset, session_id, epoch)
        doc = {"_id": f"{key}/{entry['seq']}", "key": key, "ruleset": ruleset, "session": session_id, "epoch": epoch,
               **entry}
        self.store.record_strict(LOG, [doc], stored_type="session_entry")

    def save_snapshot(self, ruleset: str, session_id: str, epoch: str, snapshot: Snapshot) -> None:
        key = _key(ruleset, session_id, epoch)
        doc = {"_id": f"{key}/s{snapshot.seq}", "key": key, "seq": snapshot.seq, "version": snapshot.version,
               "state": snapshot.state, "digest": snapshot.digest, "at": snapshot.at}
        self.store.record_strict(SNAPSHOTS, [doc], stored_type="session_snapshot")
        self._queue(("prune", key))

    def _prune(self, key: str) -> None:
        """Drop what the kept snapshots make useless: older snapshots and the entries up to the
        oldest kept one. Run after the journal shipped them (else a late shipment brings them back)."""
        kept = [d["seq"] for d in self.store.db[SNAPSHOTS].find({"key": key}, {"seq": 1})
                .sort("seq", pymongo.DESCENDING).limit(KEEP_SNAPSHOTS)]
        if len(kept) < KEEP_SNAPSHOTS:
            return
        oldest = min(kept)
        self.store.db[SNAPSHOTS].delete_many({"key": key, "seq": {"$lt": oldest}})
        self.store.db[LOG].delete_many({"key": key, "seq": {"$lte": oldest, "$gt": 0}})

    def delete(self, ruleset: str, session_id: str, epoch: str) -> None:
        """Forget a disposed session: a tombstone now (a rebuild racing the cleanup finds it
        disposed), its documents deleted in the background once the journal shipped them."""
        key = _key(ruleset, session_id, epoch)
        try:
            self.store.record_strict(LOG, [{"_id": f"{key}/disposed", "key": key, "ruleset": ruleset, "session": session_id,
                                            "epoch": epoch, "seq": -1, "kind": "disposed"}],
                                     stored_type="session_entry")
        except Exception as exc:  # the documents are still deleted below
            log.warning("session %s: no tombstone journalled: %s", key, exc)
        self._queue(("delete", key))

    def _queue(self, job: tuple[str, str]) -> None:
        try:
            self._deletions.put_nowait(job)
        except queue.Full:  # bounded: a prune is redone at the next snapshot; a deleted log waits
            log.warning("session log cleanup queue full: %s of %s left for later", job[0], job[1])

    def _delete_loop(self) -> None:
        """Cleanup, off the callers' threads: once the journal shipped a session's documents,
        prune them (after a snapshot) or delete them all (disposed)."""
        while True:
            job = self._deletions.get()
            if job is None:
                return
            what, key = job
            try:
                if not self.store.flush(self.catch_up_s):
                    raise TimeoutError("the journal has not reached the Information State")
                if what == "prune":
                    self._prune(key)
                else:
                    self.store.db[LOG].delete_many({"key": key})
                    self.store.db[SNAPSHOTS].delete_many({"key": key})
            except Exception as exc:
                log.warning("session log %s: %s not done (%s); retried later", key, what, exc)
                timer = threading.Timer(5.0, self._queue, args=(job,))
                timer.daemon = True
                timer.start()

    def close(self) -> None:
        self._deletions.put(None)

    def has_room(self, writes: int = 1) -> bool:
        return self.store.journal.room() >= writes

    def wait_shipped(self, timeout_s: float) -> bool:
        return bool(self.store.flush(timeout_s))

    # ---- reading ------------------------------------------------------------------------------
    def _index(self) -> None:
        if not self._indexed:
            self.store.db[LOG].create_index([("key", pymongo.ASCENDING), ("seq", pymongo.ASCENDING)])
            self.store.db[LOG].create_index([("ruleset", pymongo.ASCENDING), ("session", pymongo.ASCENDING),
                                             ("kind", pymongo.ASCENDING)])
            self.store.db[SNAPSHOTS].create_index([("key", pymongo.ASCENDING), ("seq", pymongo.DESCENDING)])
            self._indexed = True

    def _caught_up(self, gone: str | None) -> None:
        pids: tuple[int, ...] = ()
        host, _, pid = (gone or "").rpartition(":")
        if host == socket.gethostname() and pid.isdigit():
            pids = (int(pid),)
        if not self.store.journal.catch_up(self.catch_up_s, pids):
            raise Rebuilding("the journal has not yet reached the Information State (it is away, or slow): "
                             "the session is rebuilt once it has", retry_after_s=2)

    def history(self, ruleset: str, session_id: str, gone: str | None = None) -> History | None:
        self._caught_up(gone)
        try:
            self._index()
            openings = list(self.store.db[LOG].find({"ruleset": ruleset, "session": session_id, "kind": "open"},
                                                    {"key": 1, "at": 1}).sort("at", pymongo.DESCENDING).limit(1))
            if not openings:
                return None
            key = openings[0]["key"]
            docs = list(self.store.db[LOG].find({"key": key}).sort("seq", pymongo.ASCENDING))
            snaps = list(self.store.db[SNAPSHOTS].find({"key": key}).sort("seq", pymongo.DESCENDING).limit(KEEP_SNAPSHOTS))
        except PyMongoError as exc:
            raise Rebuilding(f"the Information State is away ({type(exc).__name__}): retry", retry_after_s=2) from None
        opening = next((d for d in docs if d.get("kind") == "open"), None)
        if opening is None:
            return None
        disposed = any(d.get("kind") == "disposed" for d in docs)
        snapshots = [Snapshot(int(d["seq"]), int(d["version"]), str(d.get("state", "")), str(d.get("digest", "")),
                              float(d.get("at", 0.0))) for d in snaps]
        entries = [_plain(d) for d in docs if d.get("kind") in ("batch", "move")]
        return History(_plain(opening), snapshots, entries, disposed)

    def stored(self, ruleset: str, session_id: str) -> bool:
        """Whether the Information State keeps a durable session by that id (its newest opening
        has no tombstone). Reads what the journal has shipped: enough to refuse a create that
        would shadow a session a stopped or dead process left (those are shipped long since)."""
        try:
            self._index()
            opening = self.store.db[LOG].find_one({"ruleset": ruleset, "session": session_id, "kind": "open"}, {"key": 1},
                                                  sort=[("at", pymongo.DESCENDING)])
            if opening is None:
                return False
            return self.store.db[LOG].find_one({"key": opening["key"], "kind": "disposed"}, {"_id": 1}) is None
        except PyMongoError as exc:
            raise Rebuilding(f"cannot tell whether session {session_id} of {ruleset} is kept: the Information State is "
                             f"away ({type(exc).__name__}); retry", retry_after_s=2) from None

    def last_activity(self, opening: dict[str, Any]) -> float:
        """When the session's newest entry was written (epoch seconds; its opening's if none)."""
        try:
            newest = self.store.db[LOG].find_one({"key": opening["key"], "seq": {"$gte": 0}}, {"at": 1},
                                                 sort=[("seq", pymongo.DESCENDING)])
        except PyMongoError:
            return time.time()  # unknown: not idle
        return float((newest or opening).get("at") or time.time())

    def sessions(self, ruleset: str | None = None) -> list[dict[str, Any]]:
        spec: dict[str, Any] = {"kind": {"$in": ["open", "disposed"]}}
        if ruleset:
            spec["ruleset"] = ruleset
        try:
            docs = list(self.store.db[LOG].find(spec, {"commands": 0}))
        except PyMongoError as exc:
            log.warning("listing durable sessions failed: %s", exc)
            return []
        gone = {d["key"] for d in docs if d.get("kind") == "disposed"}
        return [_plain(d) for d in docs if d.get("kind") == "open" and d["key"] not in gone]


def _plain(doc: dict[str, Any]) -> dict[str, Any]:
    out = dict(doc)
    out.pop("_meta", None)
    return out
