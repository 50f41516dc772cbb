"""The Information State: every sub-system's data kept in MongoDB, the way mongodb_store does it.

Each document carries ``_meta`` = {stored_type, inserted_at, inserted_by} so it can be queried by
type, time range and fields. Writes never block on the database: they are appended to a local
journal (durable against a killed process) and shipped in order by a background thread,
idempotently (each document gets its ``_id`` before it is journalled); while MongoDB is
unreachable they stay in the journal and ``health()`` says degraded.
"""

from __future__ import annotations

import logging
import math
import os
import re
import socket
import time
from datetime import datetime
from pathlib import Path
from typing import Any, Mapping

import pymongo
from bson import ObjectId
from pymongo.errors import PyMongoError

from gateway.store.journal import Journal, JournalFull, encode
from gateway.store.shipper import ShipperProcess, insert_journalled, journal_doc, mongo_client

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


RETENTION_INDEX = "retention"  # the TTL index on _meta.inserted_at (store.retention_days)


def _set_ttl(coll: Any, seconds: int) -> None:
    """Create, change (collMod) or, for 0 seconds, drop the retention TTL index of ``coll``."""
    existing = coll.index_information().get(RETENTION_INDEX)
    if seconds <= 0:
        if existing is not None:
            coll.drop_index(RETENTION_INDEX)
        return
    if existing is None:
        coll.create_index("_meta.inserted_at", name=RETENTION_INDEX, expireAfterSeconds=seconds)
    elif existing.get("expireAfterSeconds") != seconds:
        coll.database.command("collMod", coll.name, index={"name": RETENTION_INDEX, "expireAfterSeconds": seconds})


class StoreError(ValueError):
    """Bad arguments to the store (collection name, field, time range): what and where."""


class StoreUnavailable(RuntimeError):
    """A read needed the database and it is unreachable right now (writes are spooled, reads are not)."""


def check_collection(name: str) -> str:
    if not isinstance(name, str) or not COLLECTION_RE.match(name):
        raise StoreError(f"collection {name!r}: must match {COLLECTION_RE.pattern}")
    return name


_SCALARS = (str, int, bool, type(None))


def _clean(value: Any, where: str) -> Any:
    """Make a value storable: no NaN/inf (JSON can't carry them), no '$' or '.' in keys.

    Runs on every recorded decision (the fire path), so the common types are tested by exact
    type first and the place of a bad key is only spelled out when there is one."""
    kind = type(value)
    if kind in _SCALARS:
        return value
    if kind is float:
        return value if math.isfinite(value) else None
    if kind is dict or isinstance(value, Mapping):
        out = {}
        for k, v in value.items():
            key = k if type(k) is str else str(k)
            if key[:1] == "$" or "." in key:
                raise StoreError(f"{where}: field name {key!r} may not start with '$' or contain '.'")
            out[key] = _clean(v, f"{where}.{key}") if type(v) not in _SCALARS else v
        return out
    if kind is list or kind is tuple:
        return [v if type(v) in _SCALARS else _clean(v, f"{where}[{i}]") for i, v in enumerate(value)]
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    return value


class InformationState:
    """record / query / health over one MongoDB database; writes go through a local journal.

    ``record`` returns as soon as the write is in the journal (durable against a killed process,
    see :mod:`gateway.store.journal`); a background thread ships journalled writes in batches,
    idempotently, and keeps them while the database is unreachable. ``flush`` waits until they
    are in. Reads (``query``, ``count``) go to the database and raise StoreUnavailable when it is
    away. ``db`` is the pymongo database, for the modules that keep their own collections here
    (the catalog of versions, the decisions).
    """

    def __init__(self, uri: str, database: str, journal_dir: Path, *, backend: str = "external",
                 timeout_ms: int = 1000, spool_max_docs: int = 200_000, retry_interval_s: float = 1.0,
                 fsync: bool = False, linger_s: float = 0.0, ship_process: bool = False,
                 retention_days: Mapping[str, float] | None = None) -> None:
        self.uri = uri
        self.backend = backend
        self.process = process_name()  # stamped on every write (_meta.process)
        self.database = database
        self.client: pymongo.MongoClient = mongo_client(uri, timeout_ms)
        self.db = self.client[database]
        self._indexed: set[tuple[str, str]] = set()
        self.retention_days = {check_collection(c): float(d) for c, d in (retention_days or {}).items()}
        self._retained: set[str] = set()  # collections whose retention index is as configured
        # inserts made by a process of their own, off the serving process's GIL (gateway.store.shipper)
        self.shipper = ShipperProcess(uri, timeout_ms) if ship_process else None
        self.journal = Journal(Path(journal_dir), self._ship, max_docs=spool_max_docs, fsync=fsync,
                               retry_interval_s=retry_interval_s, linger_s=linger_s)

    # ---- writes -------------------------------------------------------------------------------
    def record(self, collection: str, doc: Mapping[str, Any], *, stored_type: str,
               inserted_by: str = "gateway", check_keys: bool = True) -> str:
        """Keep one document with its ``_meta``; returns its id. Never raises on a DB outage."""
        return self.record_many(collection, [doc], stored_type=stored_type, inserted_by=inserted_by,
                                check_keys=check_keys)[0]

    def record_many(self, collection: str, docs: list[Mapping[str, Any]], *, stored_type: str,
                    inserted_by: str = "gateway", check_keys: bool = True) -> list[str]:
        """Like :meth:`record` for several documents of one kind (kept in order).

        ``check_keys`` False skips the search for ``$``/``.`` field names, for documents the
        gateway builds itself from checked parts (decisions, on the fire path); a document the
        database refuses anyway is set aside by the shipper, never blocking the others."""
        check_collection(collection)
        ids, lines = [], []
        for doc in docs:
            body = _body(doc, stored_type, inserted_by, self.process)
            line = encode(self.database, collection, body)
            if check_keys and _BAD_KEY.search(line):
                _clean(dict(doc), collection)  # raises StoreError naming the field and where it is
            ids.append(body["_id"])
            lines.append(line)
        try:
            self.journal.append(self.database, collection, lines)
        except JournalFull as exc:
            log.error("Information State: %s; refused %d %s document(s) for %s (refused so far: %d)",
                      exc, len(lines), stored_type, collection, self.journal.dropped)
        return ids

    def record_strict(self, collection: str, docs: list[Mapping[str, Any]], *, stored_type: str) -> list[str]:
        """Like :meth:`record_many`, but raises :class:`JournalFull` instead of dropping: for writes
        that must be refused to their caller when they cannot be kept (a durable session's commands)."""
        check_collection(collection)
        bodies = [_body(doc, stored_type, "gateway", self.process) for doc in docs]
        lines = [encode(self.database, collection, body) for body in bodies]
        self.journal.append(self.database, collection, lines)
        return [body["_id"] for body in bodies]

    def keeps_own_indexes(self, collection: str) -> None:
        """``collection`` is indexed by its owner (e.g. the decisions): the shipper adds no generic
        ``_meta`` index to it (every index is a write per document)."""
        self._indexed.add((self.database, collection))

    def apply_retention(self, *collections: str) -> None:
        """Make the TTL index of each configured collection (all by default) say its
        ``store.retention_days``: documents older than that (by ``_meta.inserted_at``) are then
        deleted by the database itself (MongoDB's TTL monitor, SecantusDB's sweeper: once a
        minute); 0 drops the index, so nothing expires any more.

        Why TTL indexes: the high-volume collections (decisions, sensor_messages, rdf_events,
        query_results) grow with traffic for ever otherwise, and the database expiring them needs
        no job of the gateway's. The cost: one index write per stored document. Not fatal when the
        database is away: retried at the next write of that collection."""
        for collection in collections or tuple(self.retention_days):
            days = self.retention_days[collection]
            try:
                _set_ttl(self.db[collection], int(days * 86400))
            except PyMongoError as exc:
                log.warning("Information State: retention of %s not set now: %s", collection, exc)
                continue
            self._retained.add(collection)

    def flush(self, timeout_s: float = 10.0) -> bool:
        """Wait until every write made so far is in the database; False if it is not reachable."""
        return self.journal.flush(timeout_s)

    def settle(self, timeout_s: float = 1.0) -> bool:
        """Wait until this process's writes made before the call are in the database (a read of
        the database then sees them); False after ``timeout_s`` (the read goes on without them)."""
        return self.journal.settle(timeout_s)

    def _ship(self, database: str, collection: str, lines: list[bytes]) -> None:
        """Insert journalled writes (from the shipper process, or here); the documents the database
        refuses are set aside. Raises when the batch is not known to be in (it is then retried)."""
        create_index = (database, collection) not in self._indexed
        if database == self.database and collection in self.retention_days and collection not in self._retained:
            self.apply_retention(collection)
        if self.shipper is not None:
            refused = self.shipper.ship(database, collection, lines, create_index=create_index)
        else:
            refused = insert_journalled(self.client, database, collection, [journal_doc(x) for x in lines],
                                        create_index=create_index)
        self._indexed.add((database, collection))
        for index, error in refused:
            self.journal.set_aside(database, collection, journal_doc(lines[index]), error)

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

    def ping(self) -> None:
        """Raise StoreUnavailable unless the database answers now."""
        try:
            self.client.admin.command("ping")
        except PyMongoError as exc:
            raise StoreUnavailable(f"Information State unreachable at {_redact(self.uri)}: "
                                   f"{exc.__class__.__name__}: {exc}") from exc

    def health(self) -> dict[str, Any]:
        """ok / degraded with why, how many writes wait in the journal and how many were refused."""
        journal = self.journal
        return {
            "status": "degraded" if (journal.degraded or journal.dropped) else "ok",
            "backend": self.backend,
            "uri": _redact(self.uri),
            "buffered": journal.backlog,
            "dropped": journal.dropped,
            "set_aside": journal.set_aside_count,
            "last_error": journal.last_error,
        }

    def close(self, flush_timeout_s: float = 5.0) -> None:
        """Ship what can be shipped; what is left stays in the journal for the next start."""
        self.journal.close(flush_timeout_s)
        if self.shipper is not None:
            self.shipper.close()
        self.client.close()


# A key (a JSON string followed by a colon) that starts with "$" or holds a ".": MongoDB would
# take it for an operator or a path. Searched for in the encoded line, so a clean document — all of
# them on the fire path — is never walked in Python; a match is only a hint (``_clean`` then says
# exactly which field), so the pattern may over-match but never miss a key.
# Linear in the line: a key follows "{" or "," in compact JSON (so the search does not start at
# every quote inside string values), and the possessive loops ("*+") never backtrack into a long
# value. The previous pattern took 5 s a call on a 17 MB value and was quadratic in escaped quotes.
_BAD_KEY = re.compile(rb'[{,]"(?:\$|[^"\\.]*+(?:\\.[^"\\.]*+)*+\.)[^"\\]*+(?:\\.[^"\\]*+)*+":')


def process_name() -> str:
    """host:pid — which gateway process wrote something or made a decision."""
    return f"{socket.gethostname()}:{os.getpid()}"


def _body(doc: Mapping[str, Any], stored_type: str, inserted_by: str, process: str) -> dict[str, Any]:
    """The journalled form: plain JSON (``_id`` as hex text, ``inserted_at`` as epoch seconds);
    NaN and infinity become null when it is encoded. ``process`` (host:pid) tells other gateway
    processes which writes are not their own (the live relay)."""
    body = dict(doc)
    body.pop("_meta", None)
    body["_id"] = str(body.get("_id") or ObjectId())
    body["_meta"] = {"stored_type": stored_type, "inserted_at": time.time(), "inserted_by": inserted_by,
                     "process": process}
    return body


def _redact(uri: str) -> str:
    """Hide a password in a mongodb:// URI (health is public)."""
    return re.sub(r"//([^:/@]+):([^@]+)@", r"//\1:***@", uri)
