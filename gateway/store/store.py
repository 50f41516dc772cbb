"""The Information State: every sub-system's data kept in MongoDB, the way mongodb_store does it.

Each document carries ``_meta`` = {stored_type, inserted_at, inserted_by} so it can be queried by
type, time range and fields. Writes never block on a dead database: when MongoDB is unreachable
they go to a bounded on-disk spool, a background thread reconnects and flushes them in order
(idempotently: each document gets its ``_id`` before it is spooled), and ``health()`` says degraded.
"""

from __future__ import annotations

import logging
import math
import re
import threading
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Mapping

import pymongo
from bson import ObjectId
from pymongo.errors import BulkWriteError, PyMongoError

from gateway.store.spool import Spool, SpoolFull

log = logging.getLogger(__name__)

COLLECTION_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,63}$")
FIELD_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z0-9_]+)*$")
MAX_LIMIT = 1000

# The collections the gateway writes (other modules may add their own).
SENSOR_MESSAGES = "sensor_messages"
RDF_EVENTS = "rdf_events"
QUERY_RESULTS = "query_results"
RULE_FIRINGS = "rule_firings"
ACTIONS = "actions"


class StoreError(ValueError):
    """Bad arguments to the store (collection name, field, time range): what and where."""


class StoreUnavailable(RuntimeError):
    """A read needed the database and it is unreachable right now (writes are spooled, reads are not)."""


def utcnow() -> datetime:
    return datetime.now(timezone.utc)


def check_collection(name: str) -> str:
    if not isinstance(name, str) or not COLLECTION_RE.match(name):
        raise StoreError(f"collection {name!r}: must match {COLLECTION_RE.pattern}")
    return name


def _clean(value: Any, where: str) -> Any:
    """Make a value storable: no NaN/inf (JSON can't carry them), no '$' or '.' in keys."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, Mapping):
        out = {}
        for k, v in value.items():
            key = str(k)
            if key.startswith("$") or "." in key:
                raise StoreError(f"{where}: field name {key!r} may not start with '$' or contain '.'")
            out[key] = _clean(v, f"{where}.{key}")
        return out
    if isinstance(value, (list, tuple)):
        return [_clean(v, f"{where}[{i}]") for i, v in enumerate(value)]
    return value


class InformationState:
    """record / query / health over one MongoDB database, with an on-disk spool for outages."""

    def __init__(self, uri: str, database: str, spool_path: Path, *, backend: str = "external",
                 timeout_ms: int = 1000, spool_max_docs: int = 200_000, retry_interval_s: float = 1.0) -> None:
        self.uri = uri
        self.backend = backend
        self.retry_interval_s = retry_interval_s
        self.client: pymongo.MongoClient = pymongo.MongoClient(
            uri, serverSelectionTimeoutMS=timeout_ms, connectTimeoutMS=timeout_ms, socketTimeoutMS=timeout_ms * 5,
            tz_aware=True)
        self.db = self.client[database]
        self.spool = Spool(spool_path, spool_max_docs)
        self.dropped = 0
        self.last_error: str | None = None
        self._degraded = len(self.spool) > 0  # leftovers from a previous run are flushed first
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._indexed: set[str] = set()
        self._thread = threading.Thread(target=self._flusher, name="store-flusher", daemon=True)
        self._thread.start()
        if self._degraded:
            self._wake.set()

    # ---- writes -------------------------------------------------------------------------------
    def record(self, collection: str, doc: Mapping[str, Any], *, stored_type: str,
               inserted_by: str = "gateway") -> str:
        """Store one document with its ``_meta``; returns its id. Never raises on a DB outage."""
        check_collection(collection)
        body = self._body(collection, doc, stored_type, inserted_by)
        with self._lock:
            if not self._degraded:
                try:
                    self._ensure_indexes(collection)
                    self.db[collection].insert_one(body)
                    return str(body["_id"])
                except PyMongoError as exc:
                    self._go_degraded(exc)
            self._spool(collection, body)
        return str(body["_id"])

    def record_many(self, collection: str, docs: list[Mapping[str, Any]], *, stored_type: str,
                    inserted_by: str = "gateway") -> list[str]:
        """Like :meth:`record` for several documents of one kind, in one round trip (in order).

        On an outage all of them go to the spool; any that did reach the database are skipped
        when the spool is flushed (inserts are idempotent by ``_id``).
        """
        check_collection(collection)
        bodies = [self._body(collection, doc, stored_type, inserted_by) for doc in docs]
        with self._lock:
            if not self._degraded:
                try:
                    self._ensure_indexes(collection)
                    self.db[collection].insert_many(bodies, ordered=True)
                    return [str(b["_id"]) for b in bodies]
                except PyMongoError as exc:
                    self._go_degraded(exc)
            for body in bodies:
                self._spool(collection, body)
        return [str(b["_id"]) for b in bodies]

    @staticmethod
    def _body(collection: str, doc: Mapping[str, Any], stored_type: str, inserted_by: str) -> dict[str, Any]:
        body = _clean(dict(doc), collection)
        body.pop("_meta", None)
        body["_id"] = body.get("_id") or ObjectId()
        body["_meta"] = {"stored_type": stored_type, "inserted_at": utcnow(), "inserted_by": inserted_by}
        return body

    def _spool(self, collection: str, body: dict[str, Any]) -> None:
        try:
            self.spool.append(collection, body)
        except SpoolFull as exc:
            self.dropped += 1
            log.error("Information State: %s; dropped a %s document for %s (dropped so far: %d)",
                      exc, body["_meta"]["stored_type"], collection, self.dropped)

    def _go_degraded(self, exc: Exception) -> None:
        self._degraded = True
        self.last_error = f"{type(exc).__name__}: {exc}"
        log.warning("Information State unreachable (%s); buffering writes in %s", self.last_error, self.spool.path)
        self._wake.set()

    def _ensure_indexes(self, collection: str) -> None:
        if collection in self._indexed:
            return
        self.db[collection].create_index([("_meta.stored_type", 1), ("_meta.inserted_at", 1)])
        self._indexed.add(collection)

    # ---- flushing -----------------------------------------------------------------------------
    def _flusher(self) -> None:
        while not self._stop.is_set():
            self._wake.wait(self.retry_interval_s)
            self._wake.clear()
            if self._degraded and not self._stop.is_set():
                self.flush()

    def flush(self) -> bool:
        """Try to write the spool to the database; True when it is empty and the store is healthy."""
        try:
            self.client.admin.command("ping")
        except PyMongoError as exc:
            self.last_error = f"{type(exc).__name__}: {exc}"
            return False
        while True:
            pending = self.spool.read()
            if not pending:
                break
            try:
                for collection, body in pending:
                    self._insert_idempotent(collection, body)
            except PyMongoError as exc:
                self.last_error = f"{type(exc).__name__}: {exc}"
                return False
            self.spool.drop_first(len(pending))
            log.info("Information State: flushed %d buffered writes", len(pending))
        with self._lock:
            if len(self.spool) == 0:  # nothing was spooled between the last read and now
                self._degraded = False
                self.last_error = None
                return True
        return False

    def _insert_idempotent(self, collection: str, body: dict[str, Any]) -> None:
        self._ensure_indexes(collection)
        try:
            self.db[collection].insert_one(body)
        except pymongo.errors.DuplicateKeyError:
            pass  # already written before a crash/timeout: flushing twice loses and duplicates nothing
        except BulkWriteError:  # pragma: no cover - insert_one does not raise it, kept for clarity
            pass

    # ---- reads --------------------------------------------------------------------------------
    def query(self, collection: str, *, type: str | None = None, since: datetime | None = None,
              until: datetime | None = None, filters: Mapping[str, Any] | None = None,
              limit: int = 100, newest_first: bool = True) -> list[dict[str, Any]]:
        """Documents by stored type, inserted time range [since, until) and field equality filters."""
        check_collection(collection)
        if not 1 <= limit <= MAX_LIMIT:
            raise StoreError(f"limit {limit}: must be between 1 and {MAX_LIMIT}")
        if since and until and since >= until:
            raise StoreError(f"time range: since ({since.isoformat()}) must be before until ({until.isoformat()})")
        spec: dict[str, Any] = {}
        if type:
            spec["_meta.stored_type"] = type
        if since or until:
            spec["_meta.inserted_at"] = {**({"$gte": since} if since else {}), **({"$lt": until} if until else {})}
        for field, value in (filters or {}).items():
            if not FIELD_RE.match(field):
                raise StoreError(f"filter field {field!r}: must be a dotted name of letters, digits, '_'")
            spec[field] = value
        order = pymongo.DESCENDING if newest_first else pymongo.ASCENDING
        try:
            # inserted_at has millisecond resolution; _id (ObjectId: time + counter) breaks ties in order
            cursor = self.db[collection].find(spec).sort([("_meta.inserted_at", order), ("_id", order)]).limit(limit)
            docs = list(cursor)
        except PyMongoError as exc:
            raise StoreUnavailable(f"Information State unreachable: {exc.__class__.__name__}: {exc}") from exc
        for doc in docs:
            doc["_id"] = str(doc["_id"])
        return docs

    def count(self, collection: str, **spec: Any) -> int:
        """How many documents a collection holds (tests, summaries)."""
        check_collection(collection)
        try:
            return self.db[collection].count_documents(spec)
        except PyMongoError as exc:
            raise StoreUnavailable(f"Information State unreachable: {exc}") from exc

    def health(self) -> dict[str, Any]:
        """ok / degraded with why, how many writes are buffered and how many were refused."""
        return {
            "status": "degraded" if (self._degraded or self.dropped) else "ok",
            "backend": self.backend,
            "uri": _redact(self.uri),
            "buffered": len(self.spool),
            "dropped": self.dropped,
            "last_error": self.last_error,
        }

    def close(self, flush_timeout_s: float = 5.0) -> None:
        """Stop the flusher after one last flush attempt; what remains stays on disk for next start."""
        self._stop.set()
        self._wake.set()
        self._thread.join(timeout=flush_timeout_s)
        if self._degraded:
            self.flush()
        self.client.close()


def _redact(uri: str) -> str:
    """Hide a password in a mongodb:// URI (health is public)."""
    return re.sub(r"//([^:/@]+):([^@]+)@", r"//\1:***@", uri)
