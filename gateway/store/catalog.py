"""The catalog of versions in MongoDB: the source of truth every gateway process follows.

Collections (see :mod:`gateway.base.versions` for the model):

- ``catalog_versions``  ``{_id: "kind/name/n", kind, name, version, deployed_at, author, comment,
  hash, payload}`` — immutable; the payload is kept as JSON text (file names such as
  ``types.drl`` would be dotted field names in a document);
- ``catalog_heads``     ``{_id: "kind/name", kind, name, current, deleted, last, seq}``;
- ``catalog_changes``   ``{_id: seq, kind, name, event, version, author, role, comment, at, ts, origin}``
  (``event``: deploy, rollback, delete, or ``refused`` by the rule policy, which changes nothing);
- ``catalog_counters``  the global change sequence.

Concurrency without transactions (they need a replica set with a real oplog, and a single-node
SecantusDB or a standalone mongod may not offer them): a version number is claimed by inserting
its document under a unique ``_id``; the head then moves forward by compare-and-set (only to a
higher number and, for ``base_version``, only from the version that was read). Whoever loses a
race retries after a short random pause, or gets CatalogConflict when its ``base_version`` went
stale. A number claimed by a writer that died before moving the head (stored more than 10 s ago
and never made current) is skipped. The change log entry is written after the
head: a follower that sees it reads a head that already says the same or something newer.

Followers are woken by a change stream on ``catalog_changes`` when the server offers change
streams (MongoDB replica sets, SecantusDB started without ``--standalone``), else they poll.
"""

from __future__ import annotations

import json
import logging
import random
import time
from datetime import datetime, timezone
from typing import Any

from pymongo import ReturnDocument
from pymongo.errors import DuplicateKeyError, OperationFailure, PyMongoError

from gateway.base.versions import (
    Change, CatalogConflict, CatalogUnavailable, Head, Version, VersionInfo, VersionMissing, now_iso,
)

log = logging.getLogger(__name__)

VERSIONS = "catalog_versions"
HEADS = "catalog_heads"
CHANGES = "catalog_changes"
COUNTERS = "catalog_counters"
MAX_RETRIES = 100
ORPHAN_AFTER_S = 10.0


def _key(kind: str, name: str) -> str:
    return f"{kind}/{name}"


def _head(doc: dict[str, Any]) -> Head:
    return Head(doc["kind"], doc["name"], doc.get("current"), bool(doc.get("deleted")), int(doc.get("last") or 0),
                int(doc.get("seq") or 0))


def _info(doc: dict[str, Any]) -> VersionInfo:
    return VersionInfo(doc["name"], int(doc["version"]), doc.get("deployed_at", ""), doc.get("author", ""),
                       doc.get("comment", ""), doc.get("hash", ""))


def change_from_doc(doc: dict[str, Any]) -> Change:
    """A log entry from its document; KeyError/TypeError/ValueError when it is malformed."""
    version = doc.get("version")
    return Change(int(doc["seq"]), str(doc["kind"]), str(doc["name"]), str(doc["event"]),
                  None if version is None else int(version), str(doc.get("author", "")),
                  str(doc.get("comment", "")), str(doc.get("at", "")), float(doc.get("ts", 0.0)),
                  str(doc.get("origin", "")), str(doc.get("role", "")))


class MongoCatalog:
    """:class:`gateway.base.versions.Catalog` over one MongoDB database (pymongo)."""

    def __init__(self, db: Any, origin: str, *, change_streams: bool = True, poll_interval_s: float = 0.25) -> None:
        self.db = db
        self.origin = origin
        self.poll_interval_s = poll_interval_s
        self._use_change_streams = change_streams
        self._stream: Any = None
        self.skipped_changes = 0
        self._indexes()

    def _indexes(self) -> None:
        try:
            self.db[VERSIONS].create_index([("kind", 1), ("name", 1), ("version", 1)])
            self.db[HEADS].create_index([("kind", 1), ("name", 1)])
            self.db[CHANGES].create_index([("kind", 1), ("name", 1), ("_id", 1)])
        except PyMongoError as exc:
            raise CatalogUnavailable(f"the Information State is unreachable: {exc}") from exc

    # ---- reading --------------------------------------------------------------------------------
    def head(self, kind: str, name: str) -> Head | None:
        doc = self._call(self.db[HEADS].find_one, {"_id": _key(kind, name)})
        return _head(doc) if doc else None

    def heads(self, kind: str) -> list[Head]:
        docs = self._call(lambda: list(self.db[HEADS].find({"kind": kind}).sort("name", 1)))
        return [_head(d) for d in docs]

    def load(self, kind: str, name: str, version: int) -> Version:
        doc = self._call(self.db[VERSIONS].find_one, {"_id": f"{_key(kind, name)}/{int(version)}"})
        if doc is None:
            raise VersionMissing(kind, name, version)
        return Version(_info(doc), json.loads(doc["payload"]))

    def versions(self, kind: str, name: str) -> list[VersionInfo]:
        docs = self._call(lambda: list(self.db[VERSIONS].find({"kind": kind, "name": name}, {"payload": 0})
                                       .sort("version", 1)))
        return [_info(d) for d in docs]

    def history(self, kind: str, name: str) -> list[Change]:
        docs = self._call(lambda: list(self.db[CHANGES].find({"kind": kind, "name": name, "event": {"$ne": "none"}})
                                       .sort("_id", 1)))
        return [change_from_doc(d) for d in docs]

    def changes_since(self, seq: int, limit: int = 1000) -> list[Change]:
        """Log entries after ``seq``; a malformed entry is skipped with a logged reason."""
        docs = self._call(lambda: list(self.db[CHANGES].find({"_id": {"$gt": seq}}).sort("_id", 1).limit(limit)))
        out = []
        for doc in docs:
            try:
                out.append(change_from_doc(doc))
            except (KeyError, TypeError, ValueError) as exc:
                self.skipped_changes += 1
                log.error("catalog: skipped malformed change-log entry %r: %s: %s", doc.get("_id"),
                          type(exc).__name__, exc)
                out.append(Change(int(doc["_id"]), "", "", "malformed", None, "", "", "", 0.0))
        return out

    def last_seq(self) -> int:
        doc = self._call(self.db[COUNTERS].find_one, {"_id": "changes"})
        return int(doc["seq"]) if doc else 0

    # ---- changing -------------------------------------------------------------------------------
    def save(self, kind: str, name: str, payload: Any, *, author: str, comment: str, hash: str,
             base_version: int | None = None, role: str = "") -> tuple[VersionInfo, int]:
        text = json.dumps(payload, ensure_ascii=False)
        skipped = 0  # numbers claimed by writers that died before moving the head
        for attempt in range(MAX_RETRIES):
            head = self.head(kind, name)
            current = head.current if head and head.live else None
            if base_version is not None and int(base_version) != (current or 0):
                raise CatalogConflict(kind, name, int(base_version), current or 0)
            number = max(head.last if head else 0, skipped) + 1
            info = VersionInfo(name, number, now_iso(), author, comment, hash)
            try:
                self._call(self.db[VERSIONS].insert_one, {"_id": f"{_key(kind, name)}/{number}", "kind": kind,
                                                          **info.to_dict(), "payload": text})
            except DuplicateKeyError:
                if self._orphaned(kind, name, number):
                    skipped = number
                else:  # another writer is deploying right now: let it move the head, then read again
                    time.sleep(random.uniform(0.001, 0.003 * (attempt + 1)))
                continue
            seq = self._next_seq()
            if self._move_head(kind, name, head, base_version is not None, {"current": number, "last": number,
                                                                             "deleted": False, "seq": seq}):
                self._log(seq, kind, name, "deploy", number, author, comment, role)
                return info, seq
            self._call(self.db[VERSIONS].delete_one, {"_id": f"{_key(kind, name)}/{number}"})
            self._log(seq, kind, name, "none", None, author, "lost a race; retried")
        raise CatalogUnavailable(f"{kind} {name!r}: too many concurrent changes; try again")

    def _orphaned(self, kind: str, name: str, number: int) -> bool:
        """True when version ``number`` was stored long ago yet the head never reached it: its
        writer died between the two writes (a live writer moves the head within milliseconds)."""
        doc = self._call(self.db[VERSIONS].find_one, {"_id": f"{_key(kind, name)}/{number}"}, {"deployed_at": 1})
        if doc is None:
            return False
        try:
            stored = datetime.fromisoformat(str(doc.get("deployed_at", "")).replace("Z", "+00:00"))
        except ValueError:
            return True  # not written by this code: never a live deploy
        return (datetime.now(timezone.utc) - stored).total_seconds() > ORPHAN_AFTER_S

    def set_current(self, kind: str, name: str, version: int, *, author: str, comment: str,
                    role: str = "") -> tuple[VersionInfo, int]:
        stored = self.load(kind, name, version)
        seq = self._next_seq()
        self._call(self.db[HEADS].update_one, {"_id": _key(kind, name)},
                   {"$set": {"current": int(version), "deleted": False, "seq": seq}})
        self._log(seq, kind, name, "rollback", int(version), author, comment, role)
        return stored.info, seq

    def delete(self, kind: str, name: str, *, author: str, role: str = "") -> int:
        head = self.head(kind, name)
        if head is None or not head.live:
            raise VersionMissing(kind, name)
        seq = self._next_seq()
        self._call(self.db[HEADS].update_one, {"_id": _key(kind, name)},
                   {"$set": {"current": None, "deleted": True, "seq": seq}})
        self._log(seq, kind, name, "delete", None, author, "", role)
        return seq

    def refuse(self, kind: str, name: str, *, author: str, role: str, comment: str) -> int:
        seq = self._next_seq()
        self._log(seq, kind, name, "refused", None, author, comment, role)
        return seq

    def _move_head(self, kind: str, name: str, seen: Head | None, check_current: bool, new: dict[str, Any]) -> bool:
        """Move the head to ``new`` if it is still below it (and, with ``check_current``, still at
        the version that was read: the ``base_version`` check, across processes)."""
        if seen is None:
            try:
                self._call(self.db[HEADS].insert_one, {"_id": _key(kind, name), "kind": kind, "name": name, **new})
                return True
            except DuplicateKeyError:
                return False
        # the head only moves forward: to a number above the last one it pointed at
        spec: dict[str, Any] = {"_id": _key(kind, name), "last": {"$lt": new["last"]}}
        if check_current:
            spec.update({"current": seen.current, "deleted": seen.deleted})
        result = self._call(self.db[HEADS].update_one, spec, {"$set": new})
        return result.matched_count == 1

    def _next_seq(self) -> int:
        doc = self._call(self.db[COUNTERS].find_one_and_update, {"_id": "changes"}, {"$inc": {"seq": 1}},
                         upsert=True, return_document=ReturnDocument.AFTER)
        return int(doc["seq"])

    def _log(self, seq: int, kind: str, name: str, event: str, version: int | None, author: str, comment: str,
             role: str = "") -> None:
        self._call(self.db[CHANGES].insert_one, {"_id": seq, "seq": seq, "kind": kind, "name": name, "event": event,
                                                 "version": version, "author": author, "role": role, "comment": comment,
                                                 "at": now_iso(), "ts": time.time(), "origin": self.origin})

    # ---- following ------------------------------------------------------------------------------
    def wait_for_change(self, after_seq: int, timeout_s: float) -> None:
        """Wake on the change stream when there is one (else sleep a poll interval)."""
        if self._use_change_streams:
            try:
                if self._stream is None:
                    self._stream = self.db[CHANGES].watch([{"$match": {"operationType": "insert"}}],
                                                          max_await_time_ms=int(min(timeout_s, 1.0) * 1000))
                    return  # read the log once now: changes before the stream opened are not missed
                self._stream.try_next()
                return
            except OperationFailure as exc:
                log.info("catalog: no change streams on this server (%s); polling every %.2f s",
                         exc.details.get("errmsg", exc) if exc.details else exc, self.poll_interval_s)
                self._use_change_streams = False
            except PyMongoError as exc:
                log.warning("catalog: change stream interrupted (%s); reopening", exc)
                self._close_stream()
        time.sleep(min(timeout_s, self.poll_interval_s))

    def _close_stream(self) -> None:
        stream, self._stream = self._stream, None
        if stream is not None:
            try:
                stream.close()
            except PyMongoError:
                pass

    def close(self) -> None:
        self._close_stream()

    @staticmethod
    def _call(fn: Any, *args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except (DuplicateKeyError, OperationFailure) as exc:
            if isinstance(exc, DuplicateKeyError):
                raise
            raise CatalogUnavailable(f"the Information State refused a catalog operation: {exc}") from exc
        except PyMongoError as exc:
            raise CatalogUnavailable(f"the Information State is unreachable: {type(exc).__name__}: {exc}") from exc

