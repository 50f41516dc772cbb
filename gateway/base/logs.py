"""Process logging that never holds up a serving thread.

Python's logging writes to stderr under the handler's lock, in the thread that logs. When nobody
reads that stderr fast enough (a pipe its parent does not drain, a stalled terminal, a slow log
collector), the write blocks with the lock held, and then every thread that logs waits for it:
the rule sets' fire lanes, the journal that ships decisions, the member heartbeat. Seen in the
soak (bench/soak.py, whose parent left the server's stderr pipe unread): after ~640 failed-action
errors had filled the 64 KiB pipe, every fire waited for ever on the logging lock.

So every gateway process logs through a bounded queue: a thread that logs only puts the record on
the queue (never blocks; when the queue is full the record is counted and dropped), and one
writer thread writes the records to stderr. When the writer catches up after drops it says
how many records were lost. ``log_off_thread`` is called once per process by its entry point
(``printeps serve`` and its workers, the ROS launcher, ``printeps demo``, the shipper process).
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import logging.handlers
import queue
import sys
import threading
import time
from typing import Callable, TextIO

MAX_RECORDS = 10_000


class DroppingQueueHandler(logging.handlers.QueueHandler):
    """A QueueHandler that drops (and counts) a record instead of blocking when its queue is full."""

    def __init__(self, records: queue.Queue[logging.LogRecord]) -> None:
        super().__init__(records)
        self.dropped = 0

    def enqueue(self, record: logging.LogRecord) -> None:
        try:
            self.queue.put_nowait(record)
        except queue.Full:
            self.dropped += 1


class QueuedWriter:
    """The one thread that writes the queued records; before a record it says how many were dropped
    since it last said so. ``stop`` waits (bounded) for what is queued, and never hangs on a stderr
    nobody reads (``QueueListener.stop()`` would: it joins without a timeout)."""

    def __init__(self, records: queue.Queue[logging.LogRecord | None], handler: logging.Handler,
                 source: DroppingQueueHandler) -> None:
        self.records = records
        self.handler = handler
        self._source = source
        self._reported = 0
        self._thread = threading.Thread(target=self._run, name="log-writer", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def stop(self, timeout_s: float = 2.0) -> None:
        with contextlib.suppress(queue.Full):
            self.records.put(None, timeout=timeout_s)
        self._thread.join(timeout_s)

    def _run(self) -> None:
        while (record := self.records.get()) is not None:
            self._say_dropped()
            self.handler.handle(record)

    def _say_dropped(self) -> None:
        dropped = self._source.dropped
        if dropped > self._reported:
            lost, self._reported = dropped - self._reported, dropped
            self.handler.handle(logging.makeLogRecord({
                "name": __name__, "levelno": logging.WARNING, "levelname": "WARNING",
                "msg": f"{lost} log records dropped: stderr was not read fast enough (the queue holds "
                       f"{self.records.maxsize}; {dropped} dropped since start)"}))


def log_off_thread(level: int = logging.INFO, fmt: str = "%(asctime)s %(levelname)s %(name)s: %(message)s", *,
                   stream: TextIO | None = None, max_records: int = MAX_RECORDS) -> QueuedWriter:
    """Route the root logger (and so every library that propagates to it, uvicorn included when it
    is started with ``log_config=None``) through a bounded queue to ``stream`` (stderr). Returns the
    started writer; at exit it is given a moment to write what is queued."""
    records: queue.Queue[logging.LogRecord | None] = queue.Queue(max_records)
    writer = logging.StreamHandler(stream if stream is not None else sys.stderr)
    writer.setFormatter(logging.Formatter(fmt))
    handler = DroppingQueueHandler(records)
    root = logging.getLogger()
    for old in list(root.handlers):
        root.removeHandler(old)
    root.addHandler(handler)
    root.setLevel(level)
    thread = QueuedWriter(records, writer, handler)
    thread.start()
    atexit.register(thread.stop)
    return thread


class RepeatLimiter:
    """Says whether a message that repeats (same key) should be logged now: the first of each key,
    then at most one per ``window_s``, which carries how many were held back meanwhile.

    Why: some failures repeat once per decision for as long as their cause lasts (every greeting
    while no robot is connected); one line per decision buries everything else in the log and, in
    the soak, was most of it. Thread-safe; keys are few (a module and a status)."""

    def __init__(self, window_s: float = 60.0, clock: Callable[[], float] = time.monotonic) -> None:
        self.window_s = window_s
        self._clock = clock
        self._lock = threading.Lock()
        self._last: dict[object, float] = {}
        self._held: dict[object, int] = {}

    def check(self, key: object) -> tuple[bool, int]:
        """``(log it now, how many of this key were held back since the last one logged)``."""
        now = self._clock()
        with self._lock:
            last = self._last.get(key)
            if last is not None and now - last < self.window_s:
                self._held[key] = self._held.get(key, 0) + 1
                return False, 0
            self._last[key] = now
            return True, self._held.pop(key, 0)
