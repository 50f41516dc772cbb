"""The local journal: every Information State write lands here first, then goes to MongoDB.

Why a journal in front of the database:
- A write must be cheap on the hot path (a fire answered over REST must not wait for a database
  round trip) and must not be lost once it was acknowledged, even when the process is killed
  with SIGKILL a moment later. An append with ``write()`` reaches the kernel's page cache, which
  outlives the process; only a machine crash can lose it (``fsync=True`` closes that gap too, at
  the price of a disk flush per write).
- When the database is away, writes simply stay in the journal until it is back: the same path
  serves normal operation and outages (bounded by ``max_docs``; beyond that writes are refused
  and counted, never silently lost).

Layout: ``<dir>/<pid>-<start>-<n>.jsonl`` segments, one JSON document per line
(``{"db", "c", "d"}``: database, collection, document). Each process holds an exclusive
``flock`` on the segments it writes; a segment whose lock can be taken belongs to a process that
is gone (crashed, killed, restarted) and is adopted: shipped and deleted by whichever process
finds it first, which renames it ``*.jsonl.adopted`` while it ships it (so that a process that must
know every entry is in the database waits for it: :meth:`Journal.catch_up`). Shipping is
idempotent (every document carries its ``_id`` before it is journalled), so a segment shipped
twice duplicates nothing. The hand-over has races, all handled:
a segment is created locked under ``*.jsonl.new`` and only then renamed (no adopter sees it
unlocked); an adopter reads through the descriptor it locked, and only if the path still names
that file (another adopter, or the writer itself, may have shipped and deleted it meanwhile); and
the shipper thread outlives any unexpected error (tests/store/test_journal.py kills writers at
random while others adopt).
"""

from __future__ import annotations

import fcntl
import itertools
import logging
import os
import re
import threading
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Callable, Iterator, TypeVar

import orjson

log = logging.getLogger(__name__)

T = TypeVar("T")
SEGMENT_BYTES = 4 * 1024 * 1024
#: A segment's name, ``<pid>-<start ms>-<n>.jsonl``: only such files are adopted (the folder also
#: holds ``refused.jsonl``, which adopting would ship again, refuse again and set aside twice).
SEGMENT_NAME = re.compile(r"\d+-\d+-\d+\.jsonl")
NEW_SUFFIX = ".new"  # a segment being created (locked, then renamed to ``*.jsonl``)
ADOPTED_SUFFIX = ".adopted"  # a dead writer's segment another process holds and is shipping
STALE_NEW_S = 60.0  # a ``*.new`` file this old was left by a creator that died
_segment_ids = itertools.count(1)


class JournalFull(RuntimeError):
    """The journal reached its bound (``max_docs`` not yet in the database); the write was refused."""


@dataclass
class Entry:
    """One journalled write: where it goes and its journal line (shipped as it is, so what reaches
    the database is exactly what was journalled)."""

    database: str
    collection: str
    line: bytes
    segment: "Segment"


class Segment:
    """One journal file, locked by its writer for as long as it lives."""

    def __init__(self, path: Path, fd: int) -> None:
        self.path = path
        self.fd = fd
        self.size = 0
        self.written = 0   # entries appended
        self.shipped = 0   # entries known to be in the database
        self.closed = False

    @classmethod
    def create(cls, folder: Path) -> "Segment":
        """A new segment, locked before it is visible: it is created and locked under a name
        adopters do not look at (``*.jsonl.new``), then renamed. Created under its final name,
        another process could lock it first (between our open and flock), take it for an orphan
        and delete it, and our writes would go to a file nobody can find after we die."""
        path = folder / f"{os.getpid()}-{int(time.time() * 1000)}-{next(_segment_ids)}.jsonl"
        fresh = path.with_name(path.name + NEW_SUFFIX)
        fd = os.open(fresh, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        fcntl.flock(fd, fcntl.LOCK_EX)
        os.rename(fresh, path)
        return cls(path, fd)

    def append(self, line: bytes, fsync: bool) -> None:
        os.write(self.fd, line)
        if fsync:
            os.fsync(self.fd)
        self.size += len(line)
        self.written += 1

    def release(self) -> None:
        """Leave the unshipped entries for the next process: drop the shipped ones (they are a
        prefix: entries ship in the order they were written), then let go of the lock."""
        if self.closed:
            return
        self.closed = True
        if self.shipped:
            with open(self.path, "rb") as fh:
                rest = [line for line in fh if line.strip()][self.shipped:]
            tmp = self.path.with_suffix(".compact")
            tmp.write_bytes(b"".join(rest))
            os.replace(tmp, self.path)
        os.close(self.fd)

    def remove(self) -> None:
        """Delete the file (everything in it is in the database), then let go of the lock."""
        if self.closed:
            return
        self.closed = True
        try:
            os.unlink(self.path)
        except FileNotFoundError:
            pass
        os.close(self.fd)


def encode(database: str, collection: str, doc: dict[str, Any]) -> bytes:
    """One journal line (orjson: NaN and infinity become null, non-text keys text, and values it
    cannot write become their text, as JSON needs)."""
    return orjson.dumps({"db": database, "c": collection, "d": doc}, default=str,
                        option=orjson.OPT_NON_STR_KEYS) + b"\n"


def read_entries(fh: BinaryIO, path: Path) -> Iterator[tuple[str, str, bytes]]:
    """The entries of an open segment file as (database, collection, journal line); ``path`` names
    it in warnings about lines that cannot be read (skipped)."""
    for raw in fh:
        if not raw.strip():
            continue
        try:
            entry = orjson.loads(raw)
            if not (isinstance(entry["db"], str) and isinstance(entry["c"], str) and isinstance(entry["d"], dict)):
                raise TypeError("not a journal entry")
            yield entry["db"], entry["c"], raw if raw.endswith(b"\n") else raw + b"\n"
        except (orjson.JSONDecodeError, KeyError, TypeError):
            log.warning("journal %s: skipped an unreadable line (%d bytes)", path, len(raw))


def _lock_orphan(path: Path, read: bool = True) -> tuple[int, Path, list[tuple[str, str, bytes]]] | None:
    """(locked fd, its path now, entries) of the segment at ``path`` if its writer is gone; None
    if a live writer (or another adopter) holds it or it is no longer there.

    The entries are read through the locked descriptor, and only if ``path`` still names that
    file: another adopter (or its writer, shipping its last entry) may have deleted or replaced
    it between our open and our lock, and then its entries are already in the database. A
    segment read for shipping is first renamed ``*.jsonl.adopted`` (see :meth:`Journal.catch_up`)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        if not _still_named(fd, path):
            os.close(fd)
            return None
        if not read:
            return fd, path, []
        if not path.name.endswith(ADOPTED_SUFFIX):
            adopted = path.with_name(path.name + ADOPTED_SUFFIX)
            os.rename(path, adopted)
            path = adopted
        with os.fdopen(os.dup(fd), "rb") as fh:
            return fd, path, list(read_entries(fh, path))
    except BlockingIOError:
        os.close(fd)
        return None
    except OSError:
        os.close(fd)
        raise


def _still_named(fd: int, path: Path) -> bool:
    """Whether ``path`` still names the open file ``fd`` (not deleted, not replaced)."""
    opened = os.fstat(fd)
    try:
        named = os.stat(path)
    except FileNotFoundError:
        return False
    return opened.st_nlink > 0 and (named.st_dev, named.st_ino) == (opened.st_dev, opened.st_ino)


def _unlink_quietly(path: Path) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass


# ship(database, collection, journal lines of that collection, in order): raises if not all are in
Ship = Callable[[str, str, list[bytes]], None]


class Journal:
    """Appends writes durably and hands them, in order and in batches, to ``ship``.

    ``ship(database, collection, lines)`` (journal lines, see :func:`encode`) must be idempotent
    and raise on failure (meanwhile ``degraded`` is true). One daemon thread ships; :meth:`flush`
    waits until everything appended so far is shipped.

    A failed batch is retried after ``retry_interval_s``, doubled after each further failure up to
    ``MAX_BACKOFF`` times that, and in halves (down to ``MIN_BATCH``), back to full size as tries
    succeed. Why: a database that times out is mostly one that is overloaded, and it still does the
    work of the request the client gave up on; full-size retries at a fixed pace keep it there (each
    retry is again too big to finish in time), smaller and rarer ones let it catch up. A batch is
    also bounded in bytes (``batch_bytes``): an embedded engine holds a whole insert in cache until
    it commits, and 500 large decisions in one insert can come close to what it holds.
    """

    MAX_BACKOFF = 8
    MIN_BATCH = 10

    def __init__(self, folder: Path, ship: Ship, *, max_docs: int = 200_000, fsync: bool = False,
                 retry_interval_s: float = 1.0, batch: int = 500, batch_bytes: int = 1024 * 1024,
                 adopt_interval_s: float = 10.0, linger_s: float = 0.0) -> None:
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.ship = ship
        self.max_docs = max_docs
        self.fsync = fsync
        self.retry_interval_s = retry_interval_s
        self.batch = batch
        self.batch_bytes = batch_bytes
        self._batch_now = batch  # smaller after failures, back to ``batch`` as tries succeed
        self._failures = 0  # consecutive failed tries (the backoff)
        self.linger_s = linger_s  # wait this long for a batch to fill: fewer, larger inserts under load
        self._flushing = 0
        self._appended = 0  # this process's writes appended, and shipped (in order): settle() waits between
        self._shipped = 0
        self.adopt_interval_s = adopt_interval_s
        self.dropped = 0
        self.set_aside_count = 0
        self.last_error: str | None = None
        self.degraded = False
        self._pending: deque[Entry] = deque()
        self._segment: Segment | None = None
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._idle = threading.Condition(self._lock)
        self._in_hand: list[Entry] = []  # the batch being shipped (back to the queue if shipping breaks)
        self._stop = False
        self._adopted: deque[tuple[str, str, bytes]] = deque()
        self._adopted_in_hand: list[tuple[str, str, bytes]] = []  # the adopted chunk being shipped
        self._adopt_pending = 0
        self._adopted_files: list[tuple[Path, int]] = []
        self._adopt_lock = threading.Lock()  # the shipper's periodic look and catch_up() adopt one at a time
        self._adopt_orphans()  # now, so that backlog and flush() count what a dead process left
        self._thread = threading.Thread(target=self._run, name="information-state-journal", daemon=True)
        self._thread.start()

    # ---- writing -------------------------------------------------------------------------------
    def append(self, database: str, collection: str, lines: list[bytes]) -> None:
        """Journal the encoded documents (:func:`encode`, in order); raises JournalFull at the bound."""
        with self._lock:
            if self._stop:
                raise RuntimeError("the Information State journal is closed")
            if len(self._pending) + len(self._in_hand) + len(lines) > self.max_docs:
                self.dropped += len(lines)
                raise JournalFull(f"the journal in {self.folder} holds {self.max_docs} writes not yet in the database")
            segment = self._writable_segment()
            for line in lines:
                segment.append(line, self.fsync)
                self._pending.append(Entry(database, collection, line, segment))
            self._appended += len(lines)
            self._wake.notify()

    def room(self) -> int:
        """How many more writes the journal takes before it refuses (``max_docs`` not yet shipped)."""
        with self._lock:
            return self.max_docs - len(self._pending) - len(self._in_hand)

    def _writable_segment(self) -> Segment:
        if self._segment is None or self._segment.size >= SEGMENT_BYTES:
            self._segment = Segment.create(self.folder)
        return self._segment

    @property
    def backlog(self) -> int:
        """Writes not yet confirmed by the database (this process's and adopted ones)."""
        return len(self._pending) + len(self._in_hand) + self._adopt_pending

    # ---- shipping ------------------------------------------------------------------------------
    def _run(self) -> None:
        """The shipper thread. It must not die while the process lives (what it has not shipped
        would wait for the next process on this data dir): an unexpected error is logged, the
        batch in hand goes back to the front of the queue, and shipping goes on."""
        while True:
            try:
                self._ship_until_stopped()
                return
            except Exception as exc:
                log.exception("Information State journal: shipping failed unexpectedly; retrying in %.1f s",
                              self.retry_interval_s)
                self.last_error = f"{type(exc).__name__}: {exc}"
                with self._lock:
                    self._pending.extendleft(reversed(self._in_hand))
                    self._in_hand = []
                    self._adopted.extendleft(reversed(self._adopted_in_hand))
                    self._adopted_in_hand = []
                time.sleep(self.retry_interval_s)

    def _ship_until_stopped(self) -> None:
        next_adopt = time.monotonic() + self.adopt_interval_s
        while True:
            if time.monotonic() >= next_adopt:
                self._adopt_orphans()
                next_adopt = time.monotonic() + self.adopt_interval_s
            with self._lock:
                while not self._pending and not self._stop and not self._adopted:
                    self._idle.notify_all()
                    self._wake.wait(timeout=max(0.05, next_adopt - time.monotonic()))
                    if time.monotonic() >= next_adopt:
                        break
                if self._stop and not self._pending and not self._adopted:
                    self._idle.notify_all()
                    return
                deadline = time.monotonic() + self.linger_s
                while (self.linger_s and not self._stop and not self._flushing
                       and 0 < len(self._pending) < self.batch):
                    left = deadline - time.monotonic()
                    if left <= 0:
                        break
                    self._wake.wait(timeout=left)
                batch = self._take(self._pending, lambda entry: entry.line)
                self._in_hand = batch
            if batch and not self._ship_batch(batch):
                with self._lock:
                    self._pending.extendleft(reversed(batch))
                    self._in_hand = []
                if not self._back_off():
                    return
                continue
            with self._lock:
                self._in_hand = []
                self._shipped += len(batch)
                for entry in batch:
                    entry.segment.shipped += 1
                self._release_segments(batch)
                self._idle.notify_all()
            if not self._ship_adopted() and not self._back_off():
                return

    def _take(self, queue: deque[T], line_of: Callable[[T], bytes]) -> list[T]:
        """The next writes of ``queue`` to ship (this process's, or adopted ones): at most
        ``_batch_now`` of them and ``batch_bytes`` bytes (at least one)."""
        batch: list[T] = []
        size = 0
        while queue and len(batch) < self._batch_now:
            size += len(line_of(queue[0]))
            if batch and size > self.batch_bytes:
                break
            batch.append(queue.popleft())
        return batch

    def _back_off(self) -> bool:
        """After a failed try: smaller batches, and wait (longer after each failure in a row).
        False when the journal is closing (the rest stays on disk for the next process)."""
        self._failures += 1
        self._batch_now = max(self.MIN_BATCH, self._batch_now // 2)
        wait = self.retry_interval_s * min(self.MAX_BACKOFF, 2 ** min(self._failures - 1, 10))
        with self._lock:
            self._wake.wait_for(lambda: self._stop, timeout=wait)
            return not self._stop

    def _shipped_one(self) -> None:
        """After a successful try: the backoff is over, batches grow back to full size."""
        self._failures = 0
        self._batch_now = min(self.batch, self._batch_now * 2)

    def _ship_batch(self, batch: list[Entry]) -> bool:
        """Ship consecutive entries of one (database, collection) together; False on failure."""
        start = 0
        while start < len(batch):
            end = start
            key = (batch[start].database, batch[start].collection)
            while end < len(batch) and (batch[end].database, batch[end].collection) == key:
                end += 1
            if not self._try_ship(key[0], key[1], [e.line for e in batch[start:end]]):
                # what was shipped before the failure is re-shipped later: harmless (idempotent)
                return False
            start = end
        return True

    def _try_ship(self, database: str, collection: str, lines: list[bytes]) -> bool:
        try:
            self.ship(database, collection, lines)
        except Exception as exc:  # the database is away (or refuses): keep the writes, retry
            if not self.degraded:
                log.warning("Information State unreachable (%s: %s); keeping writes in %s",
                            type(exc).__name__, exc, self.folder)
            self.degraded = True
            self.last_error = f"{type(exc).__name__}: {exc}"
            return False
        if self.degraded:
            log.info("Information State reachable again; shipping the journal")
        self.degraded = False
        self.last_error = None
        self._shipped_one()
        return True

    def _release_segments(self, batch: list[Entry]) -> None:
        """Delete segments whose every entry is shipped and that take no more writes."""
        for segment in {id(e.segment): e.segment for e in batch}.values():
            if segment.shipped >= segment.written and segment is not self._segment:
                segment.remove()
        current = self._segment
        if current is not None and current.shipped >= current.written and current.size >= SEGMENT_BYTES // 4:
            current.remove()  # everything in it is shipped: start afresh instead of growing
            self._segment = None

    def set_aside(self, database: str, collection: str, doc: dict[str, Any], error: str) -> None:
        """A document the database refuses (not for being away): keep it in ``refused.jsonl``
        beside the journal with the reason, so it is not lost and holds up nothing."""
        self.set_aside_count += 1
        log.error("Information State refused a %s document (%s); kept in %s", collection, error,
                  self.folder / "refused.jsonl")
        line = orjson.dumps({"db": database, "c": collection, "d": doc, "error": error}, default=str,
                            option=orjson.OPT_NON_STR_KEYS) + b"\n"
        with open(self.folder / "refused.jsonl", "ab") as fh:
            fh.write(line)

    # ---- segments left by processes that are gone ---------------------------------------------
    def catch_up(self, timeout_s: float = 10.0, gone_pids: tuple[int, ...] = ()) -> bool:
        """Adopt every segment a gone process left here now (not at the next periodic look) and
        wait until they, and everything appended so far, are in the database; False on timeout.
        Segments another process adopted and is still shipping (``*.jsonl.adopted``, locked by
        it) are waited for too, and so are any left by ``gone_pids`` (processes of this host known
        to be dead). Why: a durable session rebuilt after its process died must read every entry
        that process acknowledged (``gateway.engine.durable``), also when a third process on the
        host happens to be shipping the dead one's journal at that moment (issue 28)."""
        deadline = time.monotonic() + timeout_s
        while True:
            found = self._adopt_orphans()
            if not self.flush(max(0.0, deadline - time.monotonic())):
                return False
            left = self._shipped_elsewhere(gone_pids)
            if not found and not left:
                return True
            if time.monotonic() >= deadline:
                return False
            if not found:
                time.sleep(0.05)  # another process is shipping them

    def _shipped_elsewhere(self, gone_pids: tuple[int, ...]) -> list[Path]:
        """Segments of dead writers still on disk and not ours to ship: adopted by another process
        (``*.jsonl.adopted``), or named after one of ``gone_pids``."""
        with self._lock:
            mine = {path for path, _fd in self._adopted_files}
        left = [p for p in self.folder.glob("*.jsonl" + ADOPTED_SUFFIX) if p not in mine]
        for pid in gone_pids:
            left += [p for p in self.folder.glob(f"{pid}-*.jsonl") if p not in mine]
        return left

    def _adopt_orphans(self) -> bool:
        """Take over unlocked segments (their writer died) and queue their entries for shipping;
        True if there may be more (one file is adopted at a time)."""
        with self._adopt_lock:
            return self._adopt_one()

    def _adopt_one(self) -> bool:
        if self._adopted:
            return True
        # *.jsonl.adopted: an adopter died before it had shipped all of a dead writer's segment
        for path in sorted([*self.folder.glob("*.jsonl"), *self.folder.glob("*.jsonl" + ADOPTED_SUFFIX)]):
            if not SEGMENT_NAME.fullmatch(path.name.removesuffix(ADOPTED_SUFFIX)):
                continue  # not a segment: refused.jsonl (what the database refused, kept as it is)
            if self._segment is not None and path == self._segment.path:
                continue
            adopted = _lock_orphan(path)
            if adopted is None:
                continue  # a live writer (or adopter) holds it, or it is gone
            fd, path, entries = adopted
            log.info("Information State: adopting %d journalled writes from %s", len(entries), path.name)
            with self._lock:
                self._adopted.extend(entries)
                self._adopt_pending += len(entries)
                self._adopted_files.append((path, fd))
                self._wake.notify()
            return True  # one file at a time keeps memory bounded
        self._clear_stale_new()
        return False

    def _clear_stale_new(self) -> None:
        """Remove ``*.jsonl.new`` files whose creator died before renaming them (they hold
        nothing: a segment is renamed before its first write). Only old ones: a young one may
        be between its creator's open and lock."""
        for path in self.folder.glob("*" + NEW_SUFFIX):
            try:
                if time.time() - path.stat().st_mtime < STALE_NEW_S:
                    continue
            except FileNotFoundError:
                continue
            adopted = _lock_orphan(path, read=False)
            if adopted is not None:
                _unlink_quietly(path)
                os.close(adopted[0])

    def _ship_adopted(self) -> bool:
        """Ship what was adopted from dead processes; False if a try failed (retried later).

        The chunk being shipped is held in ``_adopted_in_hand`` (as ``_in_hand`` holds this
        process's batch), so :meth:`flush` and :meth:`catch_up` wait for it: taken off
        ``_adopted`` and not yet in the database, it was counted nowhere, and a rebuild read the
        database without a dead owner's last acknowledged entries (issue 28)."""
        while True:
            with self._lock:
                if not self._adopted:
                    # every adopted file's entries are shipped (a file and its entries are added together)
                    files, self._adopted_files = self._adopted_files, []
                    break
                chunk = self._take(self._adopted, lambda adopted: adopted[2])
                self._adopted_in_hand = chunk
            groups: dict[tuple[str, str], list[bytes]] = {}
            for database, collection, line in chunk:
                groups.setdefault((database, collection), []).append(line)
            for (database, collection), lines in groups.items():
                if not self._try_ship(database, collection, lines):
                    with self._lock:
                        self._adopted.extendleft(reversed(chunk))
                        self._adopted_in_hand = []
                    return False
            with self._lock:
                self._adopt_pending -= len(chunk)
                self._adopted_in_hand = []
        for path, fd in files:
            _unlink_quietly(path)
            os.close(fd)
        return True

    # ---- waiting and closing ---------------------------------------------------------------------
    def flush(self, timeout_s: float = 10.0) -> bool:
        """Wait until everything appended so far is in the database; False on timeout/outage."""
        with self._lock:
            return self._wait(time.monotonic() + timeout_s, lambda: not (
                self._pending or self._in_hand or self._adopted or self._adopted_in_hand))

    def settle(self, timeout_s: float) -> bool:
        """Wait until this process's writes appended before the call are in the database (not those
        appended meanwhile, so a steady stream of writes does not hold it up); False on timeout."""
        with self._lock:
            mark = self._appended
            return self._wait(time.monotonic() + timeout_s, lambda: self._shipped >= mark)

    def _wait(self, deadline: float, done: Callable[[], bool]) -> bool:
        """(lock held) Wait until ``done()``, the shipper not lingering meanwhile; False at ``deadline``."""
        if done():
            return True
        self._flushing += 1
        self._wake.notify()
        try:
            while not done():
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._idle.wait(timeout=min(remaining, 0.05))
            return True
        finally:
            self._flushing -= 1

    def close(self, timeout_s: float = 5.0) -> None:
        """Ship what can be shipped within ``timeout_s``; what is left stays on disk for next time."""
        with self._lock:
            self._stop = True
            self._wake.notify_all()
        self._thread.join(timeout=timeout_s)
        with self._lock:
            segments = {id(e.segment): e.segment for e in self._pending}
            if self._segment is not None:
                segments[id(self._segment)] = self._segment
            for segment in segments.values():
                if segment.shipped >= segment.written:
                    segment.remove()
                else:
                    segment.release()  # unlocked: the next process adopts what is left
            for _path, fd in self._adopted_files:
                os.close(fd)
            self._adopted_files = []
