"""Inserting journalled writes into MongoDB, from a process of its own (or, optionally, a thread).

Why a process: a recorded fire is answered as soon as its decision is in the local journal; the
insert happens later, in the background. Done by a thread of the serving process, that background
work (decoding the journal lines, encoding BSON, pymongo's bookkeeping) competes with the serving
thread for the GIL: with one worker at 2 connections its p99 was 5.0–6.6 ms, against 2.3–4.6 ms
with the inserts made by this process (interleaved runs, bench/http_bench_notes.md, 2026-11-26). So each
gateway process starts one shipper process on its first write; the journal's thread only hands it
the journal lines of a batch (bytes already encoded) and waits for its answer without the GIL.

What the journal guarantees is unchanged: a batch counts as shipped only when the shipper process
answered that it is in the database. If the process dies or hangs, the batch fails like a database
outage does (retried after ``retry_interval_s``, the store says degraded meanwhile) and a new
process is started for the next try. It ends when its parent does (end of its input), and ignores
SIGINT/SIGTERM so that a Ctrl-C or a supervisor's signal to the process group still lets the parent
ship its last batches through it at shutdown.

Protocol (binary pipes): a request is one JSON header line ``{"db", "c", "index", "bytes"}`` then
``bytes`` bytes, the journal lines of one collection; the answer is one JSON line,
``{"refused": [[index, error], ...]}`` (the documents the database refused, to be set aside) or
``{"error": "..."}`` (the database is away: the whole batch is retried).
"""

from __future__ import annotations

import logging
import os
import select
import signal
import subprocess
import sys
import threading
import time
from datetime import datetime, timezone
from typing import IO, Any

import orjson
import pymongo
from bson import ObjectId
from bson.errors import InvalidDocument
from pymongo.errors import BulkWriteError, DuplicateKeyError, OperationFailure, PyMongoError

from gateway.base.logs import log_off_thread

log = logging.getLogger(__name__)

META_INDEX = [("_meta.stored_type", 1), ("_meta.inserted_at", 1)]


#: The shortest server selection a client gets, in ms: two of the drivers' minimum intervals between
#: checks of a server (``minHeartbeatFrequencyMS``, 500 ms, fixed by MongoDB's server discovery
#: specification). A client that last saw the database down checks it again at most that often, so
#: a shorter selection could end before the check that finds the database back: the first read after
#: an outage failed with "Connection refused" though the database had been up for a while
#: (``store.timeout_ms: 500``, seen in tests/store/test_store.py's 30 s outage).
MIN_SELECTION_MS = 2 * 500


def mongo_client(uri: str, timeout_ms: int) -> pymongo.MongoClient:
    """A client with the store's timeouts (the store's own reads and the shipper process use the
    same); server selection waits at least :data:`MIN_SELECTION_MS`."""
    return pymongo.MongoClient(uri, serverSelectionTimeoutMS=max(timeout_ms, MIN_SELECTION_MS),
                               connectTimeoutMS=timeout_ms, socketTimeoutMS=timeout_ms * 5, tz_aware=True)


class ShipperFailed(RuntimeError):
    """The shipper process could not ship a batch (database away, or the process died or hung)."""


def journal_doc(line: bytes) -> dict[str, Any]:
    """The document of one journal line (see :func:`gateway.store.journal.encode`)."""
    return orjson.loads(line)["d"]


def stored_form(body: dict[str, Any]) -> dict[str, Any]:
    """The stored form of a journalled document: ObjectId ``_id``, a datetime ``inserted_at``."""
    doc = dict(body)
    raw_id = doc.get("_id")
    if isinstance(raw_id, str) and ObjectId.is_valid(raw_id):
        doc["_id"] = ObjectId(raw_id)
    meta = dict(doc.get("_meta") or {})
    at = meta.get("inserted_at")
    if isinstance(at, (int, float)):
        meta["inserted_at"] = datetime.fromtimestamp(at, timezone.utc)
    doc["_meta"] = meta
    return doc


def insert_journalled(client: pymongo.MongoClient, database: str, collection: str, docs: list[dict[str, Any]],
                      *, create_index: bool) -> list[tuple[int, str]]:
    """Insert journalled documents; ones already there (an earlier, interrupted ship) are skipped.

    Returns the documents the database refused (index in ``docs``, reason), which the caller sets
    aside; raises PyMongoError when the database cannot be reached (the batch is then retried)."""
    target = client[database][collection]
    if create_index:
        target.create_index(META_INDEX)
    try:
        target.insert_many([stored_form(d) for d in docs], ordered=False)
    except BulkWriteError as exc:
        errors = exc.details.get("writeErrors", [])
        return [(e["index"], e.get("errmsg", str(e))) for e in errors if e.get("code") != 11000]
    except (InvalidDocument, OperationFailure):
        refused = []
        for index, doc in enumerate(docs):  # one refused document must not hold up the others
            try:
                target.insert_one(stored_form(doc))
            except DuplicateKeyError:
                pass
            except (InvalidDocument, OperationFailure) as single:
                refused.append((index, f"{type(single).__name__}: {single}"))
        return refused
    return []


class ShipperProcess:
    """The parent's handle on its shipper process: started on first use, restarted after a failure."""

    def __init__(self, uri: str, timeout_ms: int) -> None:
        self.uri = uri
        self.timeout_ms = timeout_ms
        self.answer_timeout_s = timeout_ms * 10 / 1000 + 5.0  # the child's own timeouts come first
        self.started = 0
        self.closed = False
        self._proc: subprocess.Popen | None = None
        self._lock = threading.Lock()

    def ship(self, database: str, collection: str, lines: list[bytes], *, create_index: bool) -> list[tuple[int, str]]:
        """Have the process insert ``lines`` (journal lines of one collection); the refused ones
        come back as (index, reason). Raises ShipperFailed when the batch is not known to be in."""
        payload = b"".join(lines)
        header = orjson.dumps({"db": database, "c": collection, "index": create_index, "bytes": len(payload)})
        with self._lock:
            proc = self._running()
            try:
                proc.stdin.write(header + b"\n" + payload)
                proc.stdin.flush()
                answer = orjson.loads(_read_line(proc.stdout, self.answer_timeout_s))
            except (OSError, ValueError, TimeoutError) as exc:
                self._stop(kill=True)
                raise ShipperFailed(f"shipper process: {type(exc).__name__}: {exc}") from None
        if "error" in answer:
            raise ShipperFailed(answer["error"])
        return [(int(i), str(reason)) for i, reason in answer["refused"]]

    def _running(self) -> subprocess.Popen:
        if self._proc is not None and self._proc.poll() is None:
            return self._proc
        if self.closed:
            raise ShipperFailed("the store is closed")
        self._stop(kill=True)
        self._proc = subprocess.Popen(
            [sys.executable, "-c", "from gateway.store.shipper import main; main()", self.uri, str(self.timeout_ms)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, close_fds=True)
        self.started += 1
        return self._proc

    def close(self, timeout_s: float = 2.0) -> None:
        """End the process: it exits at the end of its input; killed if it does not in time. Not
        under the lock: a batch still waiting for its answer (the journal gave up on it at close)
        must not hold the shutdown up; it fails, and stays in the journal for the next start."""
        self.closed = True
        self._stop(kill=False, timeout_s=timeout_s)

    def _stop(self, *, kill: bool, timeout_s: float = 2.0) -> None:
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            if kill:
                proc.kill()
            else:
                proc.stdin.close()
            proc.wait(timeout=timeout_s)
        except (OSError, ValueError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()
        finally:
            for pipe in (proc.stdin, proc.stdout):
                try:
                    pipe.close()
                except (OSError, ValueError):
                    pass


def _read_line(stream: IO[bytes], timeout_s: float) -> bytes:
    """One answer line, waiting at most ``timeout_s`` (a hung process must not stop the journal)."""
    deadline = time.monotonic() + timeout_s
    fd = stream.fileno()
    chunks: list[bytes] = []
    while True:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            raise TimeoutError(f"no answer in {timeout_s:.0f} s")
        chunk = os.read(fd, 65536)
        if not chunk:
            raise OSError("the shipper process ended")
        chunks.append(chunk)
        if chunk.endswith(b"\n"):
            return b"".join(chunks)


def serve(uri: str, timeout_ms: int, requests: IO[bytes], answers: IO[bytes]) -> None:
    """The shipper process's loop: one answer per request, until its input ends."""
    client = mongo_client(uri, timeout_ms)
    try:
        while True:
            header = requests.readline()
            if not header:
                return
            request = orjson.loads(header)
            payload = requests.read(request["bytes"])
            answers.write(orjson.dumps(_answer(client, request, payload)) + b"\n")
            answers.flush()
    finally:
        client.close()


def _answer(client: pymongo.MongoClient, request: dict[str, Any], payload: bytes) -> dict[str, Any]:
    try:
        docs = [journal_doc(line) for line in payload.splitlines() if line.strip()]
        refused = insert_journalled(client, request["db"], request["c"], docs, create_index=request["index"])
        return {"refused": refused}
    except PyMongoError as exc:
        return {"error": f"{type(exc).__name__}: {exc}"}
    except Exception as exc:  # a fault here must fail the batch (kept, retried), never end the process
        log.exception("shipper process: a batch failed")
        return {"error": f"{type(exc).__name__}: {exc}"}


def main() -> None:
    """The shipper process (started by :class:`ShipperProcess`; argv: URI, timeout in ms)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when it ends: end of input
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    log_off_thread(logging.WARNING, "shipper %(process)d: %(message)s")  # shipping never waits on stderr
    serve(sys.argv[1], int(sys.argv[2]), sys.stdin.buffer, sys.stdout.buffer)

