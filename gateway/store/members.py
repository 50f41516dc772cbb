"""The gateway processes sharing one Information State, and where each can be reached.

Why: a stateful session lives in the process that created it (its facts are in that JVM), so a
call that reaches another process must be forwarded to the owner — which needs the owner's
address, and a way to tell a busy owner from a gone one. Each serving process keeps one record
in ``members``: ``{_id: process name, url, host, pid, started_at, heartbeat_at}``, renewed every
``sessions.member_heartbeat_s`` and removed at a clean shutdown. A member whose heartbeat is
older than three intervals (or whose pid is dead on this host) is gone.

The URL is the address other processes use: ``sessions.advertise_url`` when set (several hosts),
else the process's own loopback address — for ``--workers``, each worker's private loopback port,
since the shared port may route a forwarded call back to the wrong worker.
"""

from __future__ import annotations

import logging
import os
import socket
import threading
from datetime import datetime, timedelta, timezone
from typing import Any

from pymongo.errors import PyMongoError

log = logging.getLogger(__name__)

MEMBERS = "members"


def _now() -> datetime:
    return datetime.now(timezone.utc)


class Membership:
    """This process's member record, and the others' (thread-safe; writes go straight to MongoDB)."""

    def __init__(self, db: Any, process: str, heartbeat_s: float = 5.0) -> None:
        self.db = db
        self.process = process
        self.heartbeat_s = heartbeat_s
        self.url: str | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def register(self, url: str) -> None:
        """Announces this process at ``url`` and keeps the record fresh until :meth:`close`."""
        self.url = url.rstrip("/")
        self._write()
        if self._thread is None:
            self._thread = threading.Thread(target=self._beat, name="member-heartbeat", daemon=True)
            self._thread.start()
        log.info("member %s reachable at %s", self.process, self.url)

    def _write(self) -> None:
        try:
            self.db[MEMBERS].update_one(
                {"_id": self.process},
                {"$set": {"url": self.url, "host": socket.gethostname(), "pid": os.getpid(), "heartbeat_at": _now()},
                 "$setOnInsert": {"started_at": _now()}},
                upsert=True)
        except PyMongoError as exc:  # the store is away: forwarding to us waits for the next beat
            log.warning("member record of %s not written: %s", self.process, exc)

    def _beat(self) -> None:
        while not self._stop.wait(self.heartbeat_s):
            self._write()

    def get(self, process: str) -> dict[str, Any] | None:
        try:
            return self.db[MEMBERS].find_one({"_id": process})
        except PyMongoError as exc:
            log.warning("reading member %s failed: %s", process, exc)
            return None

    def alive(self, record: dict[str, Any] | None) -> bool:
        """Whether a member record is of a live process (fresh heartbeat; a live pid on this host)."""
        if not record:
            return False
        beat = record.get("heartbeat_at")
        if isinstance(beat, datetime):
            if beat.tzinfo is None:
                beat = beat.replace(tzinfo=timezone.utc)
            if _now() - beat > timedelta(seconds=3 * self.heartbeat_s):
                return False
        if record.get("host") == socket.gethostname() and isinstance(record.get("pid"), int):
            try:
                os.kill(record["pid"], 0)
            except ProcessLookupError:
                return False
            except PermissionError:
                pass
        return True

    def members(self) -> list[dict[str, Any]]:
        try:
            return [dict(m, alive=self.alive(m)) for m in self.db[MEMBERS].find()]
        except PyMongoError as exc:
            log.warning("listing members failed: %s", exc)
            return []

    def close(self) -> None:
        self._stop.set()
        if self.url is not None:
            try:
                self.db[MEMBERS].delete_one({"_id": self.process})
            except PyMongoError:
                pass
