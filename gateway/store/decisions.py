"""One decision record: every fire from every origin, kept in the Information State.

A decision is one firing of a rule set on facts, whatever asked for it: a REST or KIE client, a
stream binding, the ROS ``fire_business_rules`` service, a workflow step (the workbench's "try it"
is no decision). Each is written to ``decisions`` with its ``decision_id`` (an ObjectId's text,
also the document ``_id``: time-ordered, so newest-first paging is an index walk), its origin, the
caller's correlation id (``X-Request-ID`` / ``traceparent`` / the ROS request), the rule set and
version, the facts in, the rules fired and the actions. Robot action outcomes are written to
``actions`` with the ``decision_id`` they carry out, so ``get`` returns a decision with them.

Each decision is built and written by the one recorder (:mod:`gateway.engine.recorder`) through
the store's journal (durable before the fire is answered, shipped in batches). This module keeps
the indexes and reads, from the database: from any process and after restarts. The last decisions
of this process are also kept in memory for a moment, so one that is not shipped yet is found anyway.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from datetime import datetime, timedelta, timezone
from typing import Any, Iterator

import pymongo
from bson import ObjectId
from bson.errors import InvalidId
from pymongo.errors import PyMongoError

from gateway.store.store import ACTIONS, StoreError, StoreUnavailable

log = logging.getLogger(__name__)

DECISIONS = "decisions"
RECENT_KEPT = 2000
MAX_PAGE = 1000
#: How long a read waits for this process's decisions recorded before it to reach the database
#: (they are shipped by the journal, normally within milliseconds; a database that is down does not
#: hold a read longer than this).
READ_OWN_S = 1.0
CORRELATION_INDEX = [("correlation_id", pymongo.ASCENDING), ("_id", pymongo.ASCENDING)]  # a trace, oldest first
# indexes earlier versions kept on decisions (see DecisionRecord._indexes)
RETIRED_INDEXES = {"origin_1__id_-1", "fired_1__id_-1", "correlation_id_1", "_meta.stored_type_1__meta.inserted_at_1"}


class DecisionRecord:
    """Reads decisions back with filters and a cursor (the recorder writes them, through ``store``)."""

    def __init__(self, store: Any) -> None:
        self.store = store
        self._recent: OrderedDict[str, dict[str, Any]] = OrderedDict()
        self._lock = threading.Lock()
        self._indexes()

    def _indexes(self) -> None:
        """Two secondary indexes: (ruleset, _id), the filter callers use most, walked newest
        first; and (correlation_id, _id), so a trace reads its chain instead of scanning.

        Why so few: every index costs each recorded fire an index write, and on the embedded
        server that is most of a decision's cost (about 0.2 ms of CPU per index per decision;
        six indexes made recording cost more than the fire). The correlation id earns its write:
        without it a trace (``GET /api/traces/{id}``, the decision page) scanned every decision,
        and its cost grew with the record (issue 29). The other filters (origin, rule, version,
        since/until) walk the ``_id`` index newest first and stop at ``limit`` matches;
        since/until are ``_id`` ranges. Indexes an older version created are dropped here.
        """
        try:
            coll = self.store.db[DECISIONS]
            self.store.keeps_own_indexes(DECISIONS)
            coll.create_index([("ruleset", pymongo.ASCENDING), ("_id", pymongo.DESCENDING)])
            coll.create_index(CORRELATION_INDEX)
            existing = coll.index_information()
            for name in RETIRED_INDEXES & set(existing):
                coll.drop_index(name)
                log.info("decisions: dropped the index %s (no longer used; it slowed every recorded fire)", name)
            self.store.db[ACTIONS].create_index([("decision_id", pymongo.ASCENDING)])
        except PyMongoError as exc:  # not fatal: indexes are created again at the next start
            log.warning("decisions: could not create indexes now: %s", exc)

    # ---- the recorder's side --------------------------------------------------------------------
    def remember(self, doc: dict[str, Any]) -> None:
        """Keep a decision the recorder (:mod:`gateway.engine.recorder`, the one writer of
        ``decisions``) just journalled, for :meth:`get` until it is shipped to the database."""
        with self._lock:
            self._recent[doc["_id"]] = doc
            while len(self._recent) > RECENT_KEPT:
                self._recent.popitem(last=False)

    # ---- reading -------------------------------------------------------------------------------
    def find(self, *, ruleset: str | None = None, version: int | None = None, origin: str | None = None,
             rule: str | None = None, since: datetime | None = None, until: datetime | None = None,
             limit: int = 50, cursor: str | None = None) -> tuple[list[dict[str, Any]], str | None]:
        """Decisions newest first with filters; returns (page, cursor of the next page or None).
        This process's decisions recorded before the call are in it (waited for up to READ_OWN_S:
        a client that fires and then lists finds its decision)."""
        if not 1 <= limit <= MAX_PAGE:
            raise StoreError(f"limit {limit}: must be between 1 and {MAX_PAGE}")
        self.store.settle(READ_OWN_S)
        spec = _spec(ruleset=ruleset, version=version, origin=origin, rule=rule, since=since, until=until,
                     cursor=cursor)
        try:
            docs = list(self.store.db[DECISIONS].find(spec, {"_meta": 0}).sort("_id", pymongo.DESCENDING)
                        .limit(limit + 1))
        except PyMongoError as exc:
            raise StoreUnavailable(f"Information State unreachable: {type(exc).__name__}: {exc}") from exc
        more = len(docs) > limit
        page = [_plain(d) for d in docs[:limit]]
        return page, (page[-1]["decision_id"] if more and page else None)

    def settle(self, timeout_s: float = 5.0) -> bool:
        """Wait until this process's decisions so far are in the database (a replay reads them
        there); False when they are not after ``timeout_s`` (the replay then misses the newest)."""
        return bool(self.store.flush(timeout_s))

    def count(self, *, ruleset: str | None = None, origin: str | None = None, since: datetime | None = None,
              until: datetime | None = None) -> int:
        """How many recorded decisions match (a replay's selection, before it reads them)."""
        try:
            return int(self.store.db[DECISIONS].count_documents(
                _spec(ruleset=ruleset, origin=origin, since=since, until=until)))
        except PyMongoError as exc:
            raise StoreUnavailable(f"Information State unreachable: {type(exc).__name__}: {exc}") from exc

    def iterate(self, *, ruleset: str | None = None, origin: str | None = None, since: datetime | None = None,
                until: datetime | None = None, limit: int = MAX_PAGE) -> Iterator[dict[str, Any]]:
        """The newest ``limit`` matching decisions, newest first, read a page at a time (a replay of
        100,000 decisions never holds them all)."""
        cursor: str | None = None
        left = limit
        while left > 0:
            page, cursor = self.find(ruleset=ruleset, origin=origin, since=since, until=until,
                                     limit=min(left, MAX_PAGE), cursor=cursor)
            yield from page
            left -= len(page)
            if cursor is None:
                return

    def by_correlation(self, correlation_id: str, limit: int = MAX_PAGE) -> list[dict[str, Any]]:
        """The decisions recorded with ``correlation_id``, oldest first (a trace; an index walk), this
        process's recorded before the call included (as :meth:`find`)."""
        self.store.settle(READ_OWN_S)
        try:
            docs = list(self.store.db[DECISIONS].find({"correlation_id": correlation_id}, {"_meta": 0})
                        .sort("_id", pymongo.ASCENDING).limit(limit))
        except PyMongoError as exc:
            raise StoreUnavailable(f"Information State unreachable: {type(exc).__name__}: {exc}") from exc
        return [_plain(d) for d in docs]

    def get(self, decision_id: str) -> dict[str, Any] | None:
        """One decision with the outcomes of its robot actions; None when unknown."""
        try:
            oid = ObjectId(decision_id)
        except (InvalidId, TypeError):
            return None
        try:
            doc = self.store.db[DECISIONS].find_one({"_id": oid}, {"_meta": 0})
            outcomes = list(self.store.db[ACTIONS].find({"decision_id": decision_id}, {"_meta": 0})
                            .sort("_id", pymongo.ASCENDING).limit(MAX_PAGE))
        except PyMongoError as exc:
            raise StoreUnavailable(f"Information State unreachable: {type(exc).__name__}: {exc}") from exc
        if doc is None:
            with self._lock:
                recent = self._recent.get(decision_id)
            if recent is None:
                return None
            doc = {k: v for k, v in recent.items() if k != "_meta"}
        out = _plain(doc)
        out["outcomes"] = [_plain(o) for o in outcomes]
        return out


#: How far a decision's id time (whole seconds, taken as it is recorded) may be from its "at".
ID_MARGIN = timedelta(seconds=5)


def at_text(moment: datetime) -> str:
    """A decision's ``at`` (UTC, ISO-8601 with milliseconds and ``Z``: text that sorts as time);
    a bound between two milliseconds is rounded up, so since/until stay inclusive/exclusive."""
    moment = moment.astimezone(timezone.utc)
    if moment.microsecond % 1000:
        moment += timedelta(microseconds=1000 - moment.microsecond % 1000)
    return moment.isoformat(timespec="milliseconds").replace("+00:00", "Z")


def at_text_ns(ns: int) -> str:
    """:func:`at_text` of the instant ``ns`` nanoseconds after the epoch (taken to the microsecond,
    as a ``datetime`` holds it), without building a datetime per call: the recorder stamps every
    decision with it, so it is on every fire's path (8 against 1.5 us). The text of the second is
    kept for the next call in the same second."""
    global _second
    ms = -(-(ns // 1000) // 1000)  # whole microseconds, rounded up to the millisecond as at_text does
    sec, frac = divmod(ms, 1000)
    kept = _second
    if kept[0] != sec:
        kept = (sec, datetime.fromtimestamp(sec, timezone.utc).replace(tzinfo=None).isoformat())
        _second = kept  # one tuple: a thread reading it meanwhile sees the old or the new pair, both right
    return f"{kept[1]}.{frac:03d}Z"


_second: tuple[int, str] = (-1, "")


def now_text() -> str:
    """The ``at`` of a decision recorded now (``at_text`` of the current UTC time)."""
    return at_text_ns(time.time_ns())


def _spec(*, ruleset: str | None = None, version: int | None = None, origin: str | None = None,
          rule: str | None = None, since: datetime | None = None, until: datetime | None = None,
          cursor: str | None = None) -> dict[str, Any]:
    """The query document of a decision selection: since/until exact on ``at`` (inclusive /
    exclusive, at its millisecond precision), the ids' time only narrowing the scan; cursor an
    ``_id`` bound."""
    spec: dict[str, Any] = {}
    for field, value in (("ruleset", ruleset), ("version", version), ("origin", origin), ("fired", rule)):
        if value is not None:
            spec[field] = value
    id_range: dict[str, Any] = {}
    at_range: dict[str, str] = {}
    # The ids' time keeps whole seconds (and is taken a moment apart from "at"): they only narrow
    # the scan, with a margin; the bounds are exact on "at".
    if since is not None:
        id_range["$gte"] = ObjectId.from_datetime(since - ID_MARGIN)
        at_range["$gte"] = at_text(since)
    if until is not None:
        id_range["$lt"] = ObjectId.from_datetime(until + ID_MARGIN)
        at_range["$lt"] = at_text(until)
    if at_range:
        spec["at"] = at_range
    if cursor is not None:
        try:
            after = ObjectId(cursor)
        except (InvalidId, TypeError):
            raise StoreError(f"cursor {cursor!r}: not a cursor this API gave out") from None
        id_range["$lt"] = min(after, id_range["$lt"]) if "$lt" in id_range else after
    if id_range:
        spec["_id"] = id_range
    return spec


def _plain(doc: dict[str, Any]) -> dict[str, Any]:
    out = dict(doc)
    out["_id"] = str(out.get("_id"))
    return out
