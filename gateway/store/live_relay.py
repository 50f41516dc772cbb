"""What the other gateway processes see happen, relayed into this process's live feed.

Why: the owner's Live view (``GET /api/live``) is served by whichever process the browser reached;
with ``--workers N`` or several hosts that process makes only a share of the decisions. Every
process already writes its decisions, robot action outcomes and stream detections to the
Information State, each stamped with the process (``_meta.process``); this relay follows those
inserts made by *other* processes and hands them to the local feed's own hooks, so every process
shows the whole teahouse.

It costs nothing while nobody watches: the change stream is opened when the feed gets its first
subscriber and closed when the last one leaves. Where the server has no change streams (a
standalone ``mongod``) it polls the collections by ``_id`` instead. Events are relayed from the
moment the stream opens (no back-fill from other processes; the feed replays its own kept events).
Readings (sensor distances) are not relayed: they arrive where the ROS node runs.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from bson import ObjectId
from pymongo.errors import OperationFailure, PyMongoError

log = logging.getLogger(__name__)

DECISIONS, ACTIONS, QUERY_RESULTS = "decisions", "actions", "query_results"
RELAYED = (DECISIONS, ACTIONS, QUERY_RESULTS)
IDLE_CHECK_S = 0.5


class LiveRelay:
    """Follows other processes' decisions, actions and detections into ``feed`` (a LiveFeed)."""

    def __init__(self, db: Any, feed: Any, process: str, *, change_streams: bool = True,
                 poll_interval_s: float = 0.5) -> None:
        self.db = db
        self.feed = feed
        self.process = process
        self.change_streams = change_streams
        self.poll_interval_s = poll_interval_s
        self.relayed = 0
        self.last_error: str | None = None
        # set while the relay follows the database (a subscriber watches and the stream or poll is
        # open): what is written from then on is relayed. Lets callers (and tests) wait on it.
        self.following = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="live-relay", daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)

    # ---- the loop ----------------------------------------------------------------------------------
    def _run(self) -> None:
        while not self._stop.is_set():
            if not self._watched():
                self._stop.wait(IDLE_CHECK_S)
                continue
            try:
                if self.change_streams:
                    self._follow_stream()
                else:
                    self._poll()
            except OperationFailure as exc:
                if self.change_streams:  # no change streams here, or not for this user: poll instead
                    log.info("live relay: no change stream on the database (%s); polling instead", exc)
                    self.change_streams = False
                    continue
                self._failed(exc)
            except PyMongoError as exc:  # the database is away: try again in a moment
                self._failed(exc)

    def _watched(self) -> bool:
        return self.feed.stats()["subscribers"] > 0 and not self.feed.closed

    def _failed(self, exc: Exception) -> None:
        self.last_error = f"{type(exc).__name__}: {exc}"
        log.warning("live relay: %s; retrying", self.last_error)
        self._stop.wait(1.0)

    def _follow_stream(self) -> None:
        """Relay inserts while someone watches; return when nobody does any more."""
        match = {"operationType": "insert", "ns.coll": {"$in": list(RELAYED)},
                 "fullDocument._meta.process": {"$ne": self.process}}
        with self.db.watch([{"$match": match}], max_await_time_ms=int(IDLE_CHECK_S * 1000)) as stream:
            self.following.set()
            try:
                while not self._stop.is_set() and self._watched():
                    change = stream.try_next()
                    if change is not None:
                        self.relay(change["ns"]["coll"], change["fullDocument"])
            finally:
                self.following.clear()

    def _poll(self) -> None:
        """Without change streams: new documents by ``_id`` (time-ordered ObjectIds) every interval."""
        since = {name: ObjectId() for name in RELAYED}  # from now on
        self.following.set()
        try:
            while not self._stop.is_set() and self._watched():
                for name, doc in self._poll_once(since):
                    self.relay(name, doc)
                self._stop.wait(self.poll_interval_s)
        finally:
            self.following.clear()

    def _poll_once(self, since: dict[str, ObjectId]) -> list[tuple[str, dict[str, Any]]]:
        """The documents written since the last tick, in the order they were recorded.

        Why two passes: reading the collections one after the other is no snapshot; a decision
        shipped while its collection had already been read would be relayed a tick after the
        detection recorded behind it. So first the newest ``_id`` anywhere (``top``), then each
        collection up to ``top``: a writer ships in the order it records (ObjectIds are made at
        record time), so everything recorded before ``top`` is in by then."""
        top = None
        for name in RELAYED:
            newest = self.db[name].find_one({"_id": {"$gt": since[name]}}, sort=[("_id", -1)], projection={"_id": 1})
            if newest is not None and (top is None or newest["_id"] > top):
                top = newest["_id"]
        if top is None:
            return []
        found = []
        for name in RELAYED:
            query = {"_id": {"$gt": since[name], "$lte": top}, "_meta.process": {"$ne": self.process}}
            docs = list(self.db[name].find(query).sort("_id", 1).limit(1000))
            found.extend((doc["_id"], name, doc) for doc in docs)
            # all of it up to top is in: past top (own documents included), or to the last one read
            since[name] = top if len(docs) < 1000 else docs[-1]["_id"]
        return [(name, doc) for _, name, doc in sorted(found, key=lambda item: item[0])]

    # ---- one document --------------------------------------------------------------------------------
    def relay(self, collection: str, doc: dict[str, Any]) -> None:
        """Hand one stored document to the feed hook that made it in its own process."""
        try:
            if collection == DECISIONS:
                self.feed.on_engine_event("fire", doc)
            elif collection == ACTIONS:
                self.feed.on_outcome(doc)
            elif collection == QUERY_RESULTS:
                self.feed.on_stream_event({**doc, "kind": "result", "solutions": doc.get("solutions")
                                           or len(doc.get("rows") or [])})
            self.relayed += 1
        except Exception:  # a malformed document is skipped, never a dead relay
            log.warning("live relay: skipped a %s document it could not show", collection, exc_info=True)
