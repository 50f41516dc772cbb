"""Write-behind for the Information State: record() returns at once, a thread does the writing.

Why: a fire answered over REST must not wait for a database round trip (with the embedded
database that is milliseconds — ten times the fire itself). Records go into a bounded queue in
order; one daemon thread hands them to the store, which itself spools to disk when the database is
away. When the queue is full, record() waits (back-pressure) rather than drop anything; close()
writes everything still queued before it returns.
"""

from __future__ import annotations

import logging
import queue
import threading
from typing import Any, Mapping

log = logging.getLogger(__name__)

_STOP = object()
MAX_BATCH = 500


class WriteBehind:
    """Queues ``record(collection, doc, stored_type=…, inserted_by=…)`` calls for a store."""

    def __init__(self, store: Any, max_queued: int = 10_000) -> None:
        self.store = store
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=max_queued)
        self._thread = threading.Thread(target=self._drain, name="information-state-writer", daemon=True)
        self._thread.start()

    def record(self, collection: str, doc: Mapping[str, Any], *, stored_type: str, inserted_by: str = "gateway") -> None:
        self._queue.put((collection, dict(doc), stored_type, inserted_by))

    def _drain(self) -> None:
        while True:
            batch = [self._queue.get()]
            while len(batch) < MAX_BATCH:  # whatever queued up meanwhile goes in the same round trip
                try:
                    batch.append(self._queue.get_nowait())
                except queue.Empty:
                    break
            stop = any(item is _STOP for item in batch)
            self._write([item for item in batch if item is not _STOP])
            if stop:
                return

    def _write(self, items: list[tuple[str, dict[str, Any], str, str]]) -> None:
        """Consecutive records of one kind in one ``record_many`` call (order kept)."""
        start = 0
        while start < len(items):
            kind = items[start][0], items[start][2], items[start][3]
            end = start
            while end < len(items) and (items[end][0], items[end][2], items[end][3]) == kind:
                end += 1
            collection, stored_type, inserted_by = kind
            docs = [item[1] for item in items[start:end]]
            if len(docs) > 1 and hasattr(self.store, "record_many"):
                self._guarded(self.store.record_many, collection, docs, stored_type, inserted_by)
            else:
                for doc in docs:
                    self._guarded(self.store.record, collection, doc, stored_type, inserted_by)
            start = end

    @staticmethod
    def _guarded(write: Any, collection: str, what: Any, stored_type: str, inserted_by: str) -> None:
        try:
            write(collection, what, stored_type=stored_type, inserted_by=inserted_by)
        except Exception:  # the store spools on outages; anything else is a bug worth a log line
            log.exception("could not record %s document(s) in %s", stored_type, collection)

    @property
    def queued(self) -> int:
        return self._queue.qsize()

    def close(self, timeout_s: float = 30.0) -> None:
        """Writes what is queued, then stops the thread."""
        self._queue.put(_STOP)
        self._thread.join(timeout=timeout_s)
        if self._thread.is_alive():
            log.error("the Information State writer did not finish within %.0f s (%d queued)", timeout_s, self.queued)
