"""Where a conversation is kept between turns: the Information State's ``conversations``.

Why in the database and not in the process that took the first turn: with ``printeps serve
--workers N``, several hosts, or the ROS node beside the REST API, a table's next turn can reach
any gateway process, and the process that took the first one may have crashed since. A
conversation's state is small (the dialogue rules' working memory between turns is the
``Conversation`` fact: the order's slots and the state), so each turn reads it here, runs the
rules and writes it back; any process continues any conversation, and a killed process loses
at most the turn it was answering (its caller got no answer and says it again).

One document per conversation::

    {_id: <conversation>, generation, rev, going_on, table, state, slots, turn, facts,
     decisions, last_decision_id, started_at, last_turn_at, last_silence_at, ended_at,
     order, order_kept, process}

- ``rev`` grows with every write: a turn is written only over the ``rev`` it read
  (compare-and-set), so two turns of one conversation at once on two processes never both
  count; the loser runs again on the winner's state.
- ``generation`` names one conversation from its first turn to its end (a finished
  conversation's next turn starts a new generation under the same ``_id``).
- ``facts`` are the session's facts after the turn, re-inserted when a process that has no
  session of that ``rev`` continues it.
- ``order``/``order_kept``: the order the rules sent to the kitchen is written with the turn that
  confirmed it (``order_kept: false``), claimed by one keeper (``"keeping"``), kept in ``orders``
  (``true``); an order still not kept a while later (its process died in between) is claimed and
  kept by whichever process's watcher finds it first.

Written straight to MongoDB, not the journal: a turn must know at once that it won. While the
database is away a turn is refused (:class:`RecordsUnavailable`, 503) rather than answered from
a state other processes cannot see. A dialogue service built without an Information State (unit
tests, the dialogue bench) keeps the same records in memory (:class:`MemoryConversations`): one
process only.

Times are wall-clock epoch seconds: they are compared across processes.
"""

from __future__ import annotations

import copy
import threading
import time
from typing import Any, Protocol

from pymongo import ASCENDING
from pymongo.errors import DuplicateKeyError, PyMongoError

CONVERSATIONS = "conversations"
MEMORY_FINISHED = 1000  # finished conversations kept in memory (a database keeps one per conversation id)


class RecordsUnavailable(RuntimeError):
    """The Information State cannot be read or written right now: the turn changed nothing."""


class ConversationRecords(Protocol):
    """The conversations' state, shared by every process of one Information State."""

    def load(self, conversation: str) -> dict[str, Any] | None: ...

    def save(self, doc: dict[str, Any], expected_rev: int | None, changes: dict[str, Any] | None = None) -> bool:
        """Writes ``doc`` if the stored one still has ``expected_rev`` (None: if there is none);
        False when another turn got there first. With ``changes``, only those fields are set
        (what :meth:`note` set since stays as it is)."""

    def note(self, conversation: str, generation: str, changes: dict[str, Any],
             decision: str | None = None) -> None:
        """Sets ``changes`` (and appends ``decision``) on that generation, whatever its ``rev``."""

    def claim_order(self, conversation: str, generation: str, stale_before: float) -> bool:
        """Marks that generation's order as being kept by the caller (``order_kept: "keeping"``)
        unless it is kept, or being kept by a claim made after ``stale_before``: one keeper."""

    def count_going_on(self) -> int: ...

    def going_on(self, limit: int) -> list[dict[str, Any]]: ...

    def finished(self, limit: int) -> list[dict[str, Any]]: ...

    def quiet(self, before: float) -> list[dict[str, Any]]:
        """Conversations going on with no turn and no silence told since ``before``."""

    def stale(self, before: float) -> list[dict[str, Any]]:
        """Conversations going on with no turn since ``before``."""

    def unkept_orders(self, before: float) -> list[dict[str, Any]]:
        """Conversations whose order was written (or claimed) before ``before`` but not kept."""


class MongoConversations:
    """:class:`ConversationRecords` in the Information State's ``conversations`` collection."""

    def __init__(self, db: Any) -> None:
        self.collection = db[CONVERSATIONS]
        self._indexed = False  # made at the first use, not at start-up (the database may be away then)

    def _do(self, what: str, call: Any) -> Any:
        try:
            if not self._indexed:
                self.collection.create_index([("going_on", ASCENDING), ("last_turn_at", ASCENDING)])
                self._indexed = True
            return call()
        except DuplicateKeyError:
            raise
        except PyMongoError as exc:
            raise RecordsUnavailable(f"the Information State is unreachable ({what} conversations: "
                                     f"{type(exc).__name__}); the turn changed nothing, say it again") from None

    def load(self, conversation: str) -> dict[str, Any] | None:
        return self._do("reading", lambda: self.collection.find_one({"_id": conversation}))

    def save(self, doc: dict[str, Any], expected_rev: int | None, changes: dict[str, Any] | None = None) -> bool:
        if expected_rev is None:
            try:
                self._do("writing", lambda: self.collection.insert_one(dict(doc)))
                return True
            except DuplicateKeyError:
                return False
        where = {"_id": doc["_id"], "rev": expected_rev}
        if changes is not None:
            done = self._do("writing", lambda: self.collection.update_one(where, {"$set": changes}))
        else:
            done = self._do("writing", lambda: self.collection.replace_one(where, doc))
        return done.matched_count == 1

    def note(self, conversation: str, generation: str, changes: dict[str, Any], decision: str | None = None) -> None:
        update: dict[str, Any] = {"$set": changes} if changes else {}
        if decision is not None:
            update["$push"] = {"decisions": decision}
        if update:
            self._do("writing", lambda: self.collection.update_one({"_id": conversation, "generation": generation},
                                                                   update))

    def claim_order(self, conversation: str, generation: str, stale_before: float) -> bool:
        where = {"_id": conversation, "generation": generation, "$or": [
            {"order_kept": False}, {"order_kept": "keeping", "order_claimed_at": {"$lte": stale_before}}]}
        done = self._do("writing", lambda: self.collection.update_one(
            where, {"$set": {"order_kept": "keeping", "order_claimed_at": time.time()}}))
        return done.modified_count == 1

    def count_going_on(self) -> int:
        return int(self._do("counting", lambda: self.collection.count_documents({"going_on": True})))

    def going_on(self, limit: int) -> list[dict[str, Any]]:
        return self._do("listing", lambda: list(self.collection.find({"going_on": True}).sort("last_turn_at", -1)
                                                 .limit(limit)))

    def finished(self, limit: int) -> list[dict[str, Any]]:
        return self._do("listing", lambda: list(self.collection.find({"going_on": False}).sort("ended_at", -1)
                                                 .limit(limit)))

    def quiet(self, before: float) -> list[dict[str, Any]]:
        return self._do("reading", lambda: list(self.collection.find(
            {"going_on": True, "last_turn_at": {"$lte": before}, "last_silence_at": {"$lte": before}})))

    def stale(self, before: float) -> list[dict[str, Any]]:
        return self._do("reading", lambda: list(self.collection.find(
            {"going_on": True, "last_turn_at": {"$lte": before}})))

    def unkept_orders(self, before: float) -> list[dict[str, Any]]:
        return self._do("reading", lambda: list(self.collection.find(
            {"$or": [{"order_kept": False, "order_at": {"$lte": before}},
                     {"order_kept": "keeping", "order_claimed_at": {"$lte": before}}]})))


class MemoryConversations:
    """:class:`ConversationRecords` in this process only (a gateway without an Information State)."""

    def __init__(self) -> None:
        self._docs: dict[str, dict[str, Any]] = {}
        self._lock = threading.Lock()

    def load(self, conversation: str) -> dict[str, Any] | None:
        with self._lock:
            doc = self._docs.get(conversation)
            return copy.deepcopy(doc) if doc is not None else None

    def save(self, doc: dict[str, Any], expected_rev: int | None, changes: dict[str, Any] | None = None) -> bool:
        with self._lock:
            current = self._docs.get(doc["_id"])
            if (current is None) != (expected_rev is None) or (current is not None and current["rev"] != expected_rev):
                return False
            if current is not None and changes is not None:
                current.update(copy.deepcopy(changes))
            else:
                self._docs[doc["_id"]] = copy.deepcopy(doc)
            self._forget_oldest_finished()
            return True

    def _forget_oldest_finished(self) -> None:
        finished = sorted((d for d in self._docs.values() if not d["going_on"]), key=lambda d: d.get("ended_at") or 0)
        for doc in finished[:max(0, len(finished) - MEMORY_FINISHED)]:
            del self._docs[doc["_id"]]

    def note(self, conversation: str, generation: str, changes: dict[str, Any], decision: str | None = None) -> None:
        with self._lock:
            doc = self._docs.get(conversation)
            if doc is None or doc.get("generation") != generation:
                return
            doc.update(copy.deepcopy(changes))
            if decision is not None:
                doc.setdefault("decisions", []).append(decision)

    def _where(self, test: Any) -> list[dict[str, Any]]:
        with self._lock:
            return [copy.deepcopy(d) for d in self._docs.values() if test(d)]

    def claim_order(self, conversation: str, generation: str, stale_before: float) -> bool:
        with self._lock:
            doc = self._docs.get(conversation)
            if doc is None or doc.get("generation") != generation or not _claimable(doc, stale_before):
                return False
            doc.update(order_kept="keeping", order_claimed_at=time.time())
            return True

    def count_going_on(self) -> int:
        return len(self._where(lambda d: d["going_on"]))

    def going_on(self, limit: int) -> list[dict[str, Any]]:
        return sorted(self._where(lambda d: d["going_on"]), key=lambda d: -d["last_turn_at"])[:limit]

    def finished(self, limit: int) -> list[dict[str, Any]]:
        return sorted(self._where(lambda d: not d["going_on"]), key=lambda d: -(d.get("ended_at") or 0))[:limit]

    def quiet(self, before: float) -> list[dict[str, Any]]:
        return self._where(lambda d: d["going_on"] and d["last_turn_at"] <= before and d["last_silence_at"] <= before)

    def stale(self, before: float) -> list[dict[str, Any]]:
        return self._where(lambda d: d["going_on"] and d["last_turn_at"] <= before)

    def unkept_orders(self, before: float) -> list[dict[str, Any]]:
        return self._where(lambda d: (d.get("order_kept") is False and (d.get("order_at") or 0) <= before)
                           or (d.get("order_kept") == "keeping" and (d.get("order_claimed_at") or 0) <= before))


def _claimable(doc: dict[str, Any], stale_before: float) -> bool:
    kept = doc.get("order_kept")
    return kept is False or (kept == "keeping" and (doc.get("order_claimed_at") or 0) <= stale_before)
