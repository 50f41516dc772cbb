"""Which process owns which stateful session, in the Information State (``sessions``).

``{_id: "<ruleset>/<session id>", ruleset, session, process, url, kind, clock, on_deploy,
created_at}``. A process claims a session before creating it (an insert under the unique
``_id``: two processes asked for the same declared ksession at once make one session), releases
it when the session is disposed, and any process asked for a session it does not hold looks the
owner up here — to forward the call (see ``gateway.api.forwarding``), or to answer 410 when the
owner is gone. Written straight to MongoDB (not the journal): a claim must be decided at once.
While the database is away, sessions still work in the process that holds them.
"""

from __future__ import annotations

import logging
from datetime import datetime, timezone
from typing import Any

from pymongo.errors import DuplicateKeyError, PyMongoError

log = logging.getLogger(__name__)

SESSIONS = "sessions"


class SessionDirectory:
    """The ``sessions`` records of one Information State, for process ``process``."""

    def __init__(self, db: Any, process: str, members: Any) -> None:
        self.db = db
        self.process = process
        self.members = members  # gateway.store.members.Membership

    @staticmethod
    def key(ruleset: str, session_id: str) -> str:
        return f"{ruleset}/{session_id}"

    def claim(self, ruleset: str, session_id: str, info: dict[str, Any]) -> dict[str, Any]:
        record = {"_id": self.key(ruleset, session_id), "ruleset": ruleset, "session": session_id,
                  "process": self.process, "url": self.members.url, "created_at": datetime.now(timezone.utc), **info}
        try:
            self.db[SESSIONS].insert_one(record)
            return record
        except DuplicateKeyError:
            existing = self.db[SESSIONS].find_one({"_id": record["_id"]})
            return existing or record
        except PyMongoError as exc:
            log.warning("session %s/%s not recorded (the Information State is away): %s", ruleset, session_id, exc)
            return record

    def take(self, ruleset: str, session_id: str, dead: str, info: dict[str, Any]) -> bool:
        """Compare-and-set: this process becomes the owner if ``dead`` (a gone process) still is.
        Of processes racing to take over a durable session exactly one wins; the others forward."""
        try:
            result = self.db[SESSIONS].update_one(
                {"_id": self.key(ruleset, session_id), "process": dead},
                {"$set": {"process": self.process, "url": self.members.url, "taken_from": dead,
                          "taken_at": datetime.now(timezone.utc), **info}})
            return result.modified_count == 1
        except PyMongoError as exc:
            log.warning("taking over session %s/%s failed: %s", ruleset, session_id, exc)
            return False

    def alive(self, record: dict[str, Any]) -> bool:
        """Whether the process owning ``record`` is alive (its member record, see Membership.alive)."""
        process = record.get("process")
        return bool(process) and self.members.alive(self.members.get(str(process)))

    def owner(self, ruleset: str, session_id: str) -> dict[str, Any] | None:
        try:
            return self.db[SESSIONS].find_one({"_id": self.key(ruleset, session_id)})
        except PyMongoError as exc:
            log.warning("looking up session %s/%s failed: %s", ruleset, session_id, exc)
            return None

    def release(self, ruleset: str, session_id: str, process: str | None = None) -> None:
        """Forgets the record if ``process`` (default: this one) still owns it."""
        self.db[SESSIONS].delete_one({"_id": self.key(ruleset, session_id), "process": process or self.process})

    def records(self, ruleset: str | None = None) -> list[dict[str, Any]]:
        try:
            return list(self.db[SESSIONS].find({"ruleset": ruleset} if ruleset else {}))
        except PyMongoError as exc:
            log.warning("listing sessions failed: %s", exc)
            return []

    def release_all(self) -> None:
        """At a clean shutdown: this process's sessions end with it."""
        try:
            self.db[SESSIONS].delete_many({"process": self.process})
        except PyMongoError:
            pass
