"""Bulkheads: each rule set fires on its own few threads, behind a bounded queue with a maximum wait.

Why: a fire is a JVM call that blocks its thread. Run on the event loop, one slow rule set (a big
join, a large accumulate) delays every other request of the process — other rule sets' fires,
``/health``, the workbench, the live feed. Here each rule set gets ``api.fire_workers`` threads of
its own (started on demand, gone after idling), so a slow set uses its own share and the others go
on; the event loop only parses, routes and answers. JPype releases the GIL while in Java, so the
threads overlap with the loop.

Admission control: a fire that would queue behind ``api.max_queue`` others is refused at once
(:class:`Overloaded` ``queue_full``, 429); one that would wait longer than ``api.max_wait_s`` (by the
rule set's recent fire time) is refused at once too, and one that did wait longer after all is
refused when its turn comes instead of running late (``waited``, 503). Both carry a
``Retry-After``. Nothing refused has been fired, so nothing is lost: the caller retries.

Two lanes, one accounting. A stateless fire (the REST fire route, the hot path) runs on the rule
set's JVM threads (:meth:`Bulkhead.fire`, ``java/.../FireLane.java``): they never take the GIL, so
the event loop is not competed with; the answers come back through a pipe the loop watches, every
answer that finished meanwhile in one drain (:class:`_Inbox`). Measured on 2 cores, a Python worker
thread there cost a quarter of the REST fire's throughput (docs/benchmarks.md). Any other work
(session commands, KIE batches: Python orchestrating several Java calls) runs on the rule set's
Python threads (:meth:`Bulkhead.run`): a C ``SimpleQueue`` the workers block on, the answers handed
back to the loop in batches (one ``call_soon_threadsafe`` for the answers that finish while the
loop is busy). Both lanes count against the same queue bound and wait estimate.
"""

from __future__ import annotations

import asyncio
import collections
import itertools
import math
import os
import queue
import shutil
import tempfile
import threading
import time
import weakref
from typing import Any, Callable

import orjson

from gateway.base import jvm
from gateway.engine.errors import Overloaded
from gateway.engine.results import PreparedFire

Done = Callable[[Any, BaseException | None], None]

#: Weight of the newest fire in a rule set's mean fire time (the wait estimate).
SMOOTHING = 0.2

#: A JVM-lane answer's elapsed time when the fire was refused for waiting too long (as
#: FireLane.java writes it), and when it never reached the JVM (its submission failed).
WAITED = -1
NOT_SUBMITTED = -2


class Bulkhead:
    """One rule set's fire threads and queue (thread-safe)."""

    def __init__(self, name: str, workers: int, max_queue: int, max_wait_s: float, idle_s: float = 30.0) -> None:
        self.name = name
        self.workers = max(1, workers)
        self.max_queue = max_queue
        self.max_wait_s = max_wait_s
        self.idle_s = idle_s
        self._queue: queue.SimpleQueue[tuple[Callable[[], Any], Done, float]] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self.waiting = 0  # submitted, not yet taken by a worker
        self.running = 0
        self.threads = 0
        self.in_java = 0  # stateless fires submitted to the JVM lane, not yet answered
        self.mean_s = 0.0
        self.refused = {"queue_full": 0, "waited": 0}
        self._java_lane: Any = None

    # -- submitting ---------------------------------------------------------------------------------
    def submit(self, fn: Callable[[], Any], done: Done) -> None:
        """Queue ``fn`` for a worker, which calls ``done(result, error)`` when it ran (or was refused
        for waiting too long); raises :class:`Overloaded` at once when it would not be served in time."""
        with self._lock:
            self._admit()
            self.waiting += 1
            spawn = self.threads < self.workers and self.threads < self.waiting + self.running
            if spawn:
                self.threads += 1
        self._queue.put((fn, done, time.monotonic()))
        if spawn:
            threading.Thread(target=self._work, name=f"fire-{self.name}", daemon=True).start()

    async def run(self, fn: Callable[[], Any]) -> Any:
        """``fn()``'s result, computed on a worker while the event loop goes on."""
        loop = asyncio.get_running_loop()
        future = loop.create_future()
        inbox = _inbox_of(loop)

        def done(result: Any, error: BaseException | None) -> None:
            inbox.deliver(future, result, error)

        self.submit(fn, done)
        return await future

    async def fire(self, prepared: PreparedFire, timeout_ms: int) -> tuple[dict[str, Any], float]:
        """``prepared``'s fire on this rule set's JVM threads while the event loop goes on: the
        Runner's parsed answer and the fire's duration in ms. Raises :class:`Overloaded` as
        :meth:`submit` does, at once or when a thread takes it too late."""
        loop = asyncio.get_running_loop()
        with self._lock:
            self._admit()
            self.in_java += 1
            lane = self._java_lane
        try:
            if lane is None:
                lane = self._lane()
            future = _inbox_of(loop).fire(self, lane, prepared, timeout_ms)
        except BaseException:
            with self._lock:
                self.in_java -= 1
            raise
        return await future

    def _lane(self) -> Any:
        with self._lock:
            if self._java_lane is None:
                self._java_lane = jvm.helper_class("FireLane")(self.name, self.workers, int(self.idle_s * 1000))
            return self._java_lane

    def _answered_in_java(self, elapsed_ns: int, waited_ns: int) -> Overloaded | None:
        """Counts a JVM-lane fire as answered (on the loop); the refusal when it waited too long
        (``elapsed_ns`` :data:`WAITED`; :data:`NOT_SUBMITTED`: it never reached the JVM)."""
        with self._lock:
            self.in_java -= 1
            if elapsed_ns == NOT_SUBMITTED:
                return None
            if elapsed_ns == WAITED:
                self.refused["waited"] += 1
                return self._refusal("waited", waited_ns / 1e9)
            self._ran(elapsed_ns / 1e9)
            return None

    def _ran(self, elapsed: float) -> None:
        """A fire took ``elapsed`` seconds: the mean the wait estimate uses (under the lock)."""
        self.mean_s = elapsed if self.mean_s == 0.0 else self.mean_s + SMOOTHING * (elapsed - self.mean_s)

    # -- the workers --------------------------------------------------------------------------------
    def _work(self) -> None:
        while True:
            try:
                fn, done, queued_at = self._queue.get(timeout=self.idle_s)
            except queue.Empty:
                with self._lock:
                    if self.waiting == 0:  # nothing was queued meanwhile: this thread is not needed
                        self.threads -= 1
                        return
                continue
            self._serve(fn, done, time.monotonic() - queued_at)

    def _serve(self, fn: Callable[[], Any], done: Done, waited: float) -> None:
        with self._lock:
            self.waiting -= 1
            late = waited > self.max_wait_s
            if late:
                self.refused["waited"] += 1
            else:
                self.running += 1
        if late:
            _call_done(done, None, self._refusal("waited", waited))
            return
        started = time.monotonic()
        result: Any = None
        error: BaseException | None = None
        try:
            result = fn()
        except BaseException as exc:  # handed to the caller, whatever it is
            error = exc
        elapsed = time.monotonic() - started
        with self._lock:
            self.running -= 1
            self._ran(elapsed)
        _call_done(done, result, error)

    # -- limits -------------------------------------------------------------------------------------
    def _admit(self) -> None:
        """Raises :class:`Overloaded` when a fire submitted now would not be served in time (under the lock)."""
        if self._queued() >= self.max_queue:
            self.refused["queue_full"] += 1
            raise self._refusal("queue_full", self._expected_wait())
        expected = self._expected_wait()
        if expected > self.max_wait_s:
            self.refused["waited"] += 1
            raise self._refusal("waited", expected)

    def _queued(self) -> int:
        """Fires waiting for a thread, in both lanes (under the lock)."""
        return self.waiting + max(0, self.in_java - self.workers)

    def _expected_wait(self) -> float:
        """How long a fire submitted now would wait, by the recent mean fire time (under the lock)."""
        return self.mean_s * (self.waiting + self.running + self.in_java) / self.workers

    def _refusal(self, reason: str, wait_s: float) -> Overloaded:
        retry = max(1, math.ceil(min(wait_s, 3600.0)))
        if reason == "queue_full":
            return Overloaded(self.name, reason, self.max_queue, "api.max_queue", retry,
                              f"rule set {self.name!r} is overloaded: {self.max_queue} fires are already queued "
                              f"(api.max_queue); retry in {retry} s")
        return Overloaded(self.name, reason, self.max_wait_s, "api.max_wait_s", retry,
                          f"rule set {self.name!r} is overloaded: a fire would wait {wait_s:.1f} s, longer than "
                          f"{self.max_wait_s:g} s (api.max_wait_s); retry in {retry} s")

    def stats(self) -> dict[str, Any]:
        java_threads = 0 if self._java_lane is None else int(self._java_lane.threads())
        with self._lock:
            return {"waiting": self._queued(), "running": self.running + min(self.in_java, self.workers),
                    "threads": self.threads + java_threads, "mean_fire_ms": round(self.mean_s * 1000, 3),
                    "refused": dict(self.refused)}


class _Inbox:
    """The answers of every bulkhead for one event loop, settled there in batches.

    Why: each ``call_soon_threadsafe`` writes to the loop's wake-up pipe (a system call, and a
    wake-up the loop reads back). Answers that finish while a drain is already scheduled join it,
    so a busy loop is woken once for them all instead of once per fire. The JVM lane's answers wait
    in a Java queue (``FireLane.Inbox``) whose first answer after a drain writes one byte to a pipe
    the loop reads; the loop then takes them all in one call. The loop is held weakly: an inbox
    outlives no loop."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = weakref.ref(loop)
        self._answers: collections.deque[tuple[asyncio.Future[Any], Any, BaseException | None]] = collections.deque()
        self._scheduled = False
        self._java: Any = None  # FireLane.Inbox, made at the first JVM-lane fire
        self._read_fd = -1
        self._tickets = itertools.count()
        self._pending: dict[int, tuple[asyncio.Future[Any], Bulkhead]] = {}
        self._unsubmitted: list[tuple[Any, int, PreparedFire, int, int]] = []

    def deliver(self, future: asyncio.Future[Any], result: Any, error: BaseException | None) -> None:
        """From a worker: settle ``future`` on the loop (raises RuntimeError once the loop closed)."""
        self._answers.append((future, result, error))
        if not self._scheduled:  # two workers may both schedule a drain: the second finds it done
            self._scheduled = True
            loop = self._loop()
            try:
                if loop is None:
                    raise RuntimeError("the event loop is gone")
                loop.call_soon_threadsafe(self._drain)
            except RuntimeError:
                self._scheduled = False
                raise

    def _drain(self) -> None:
        self._scheduled = False  # first: an answer added from now on schedules the next drain
        answers = self._answers
        while answers:
            _settle(*answers.popleft())

    # -- the JVM lane (on the loop) ---------------------------------------------------------------
    def fire(self, bulkhead: Bulkhead, lane: Any, prepared: PreparedFire, timeout_ms: int) -> asyncio.Future[Any]:
        """Submits ``prepared`` to ``lane``; the future gets ``(answer, ms)`` or the refusal."""
        if self._java is None:
            self._open_java()
        loop = self._loop()
        assert loop is not None  # called on it
        future = loop.create_future()
        ticket = next(self._tickets)
        self._pending[ticket] = (future, bulkhead)
        # submitted at the end of this loop iteration, with every other fire that came in it: one JVM
        # call, and one thread wake-up, for them all (a wake-up is the dear part of a hand-off)
        self._unsubmitted.append((lane, ticket, prepared, timeout_ms, int(bulkhead.max_wait_s * 1000)))
        if len(self._unsubmitted) == 1:
            loop.call_soon(self._submit)
        return future

    def _submit(self) -> None:
        batch, self._unsubmitted = self._unsubmitted, []
        groups: dict[tuple[Any, ...], list[tuple[int, PreparedFire]]] = {}
        for lane, ticket, prepared, timeout_ms, max_wait_ms in batch:
            key = (lane, prepared.limit, prepared.return_facts, prepared.record_facts, timeout_ms, max_wait_ms)
            groups.setdefault(key, []).append((ticket, prepared))
        for (lane, limit, return_facts, record_facts, timeout_ms, max_wait_ms), fires in groups.items():
            try:
                if len(fires) == 1:
                    ticket, prepared = fires[0]
                    lane.fire(self._java, ticket, prepared.runner, prepared.facts_json, limit, return_facts, record_facts,
                              timeout_ms, max_wait_ms)
                else:
                    lane.fireMany(self._java, [t for t, _ in fires], [p.runner for _, p in fires],
                                  [p.facts_json for _, p in fires], limit, return_facts, record_facts, timeout_ms, max_wait_ms)
            except Exception as exc:  # the JVM refused the submission (e.g. out of memory): those fires fail
                for ticket, _ in fires:
                    self._fail(ticket, exc)

    def _fail(self, ticket: int, error: BaseException) -> None:
        future, bulkhead = self._pending.pop(ticket)
        bulkhead._answered_in_java(NOT_SUBMITTED, 0)
        if not future.cancelled():
            future.set_exception(error)

    def _open_java(self) -> None:
        loop = self._loop()
        assert loop is not None
        # a named pipe, so that Java opens its write end by a path on any POSIX system; the name
        # goes as soon as both ends are open
        folder = tempfile.mkdtemp(prefix="printeps-lane-")
        path = os.path.join(folder, "wake")
        try:
            os.mkfifo(path, 0o600)
            read_end = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)  # first: Java's open then does not block
            try:
                self._java = jvm.helper_class("FireLane").Inbox(path)
            except BaseException:
                os.close(read_end)
                raise
        finally:
            shutil.rmtree(folder, ignore_errors=True)
        self._read_fd = read_end
        loop.add_reader(read_end, self._drain_java)
        weakref.finalize(loop, _close_java, read_end, self._java)

    def _drain_java(self) -> None:
        try:
            os.read(self._read_fd, 4096)
        except (BlockingIOError, OSError):
            pass
        text = str(self._java.drain())
        if text == "[]":
            return
        for ticket, elapsed_ns, answer in orjson.loads(text):
            found = self._pending.pop(ticket, None)
            if found is None:  # failed at its submission already (_fail), though the JVM took it
                continue
            future, bulkhead = found
            refusal = bulkhead._answered_in_java(elapsed_ns, answer if elapsed_ns == WAITED else 0)
            if future.cancelled():  # the caller went away
                continue
            if refusal is not None:
                future.set_exception(refusal)
            else:
                future.set_result((answer, elapsed_ns / 1e6))


_inboxes: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, _Inbox] = weakref.WeakKeyDictionary()
_inboxes_lock = threading.Lock()


def _inbox_of(loop: asyncio.AbstractEventLoop) -> _Inbox:
    found = _inboxes.get(loop)
    if found is None:
        with _inboxes_lock:
            found = _inboxes.setdefault(loop, _Inbox(loop))
    return found


def _close_java(read_fd: int, java_inbox: Any) -> None:
    """A loop's JVM-lane inbox is closed with the loop (its pipe, and Java's end of it)."""
    try:
        os.close(read_fd)
    except OSError:
        pass
    try:
        java_inbox.close()
    except Exception:  # the JVM is shutting down
        pass


def _settle(future: asyncio.Future[Any], result: Any, error: BaseException | None) -> None:
    if future.cancelled():  # the caller went away
        return
    if error is not None:
        future.set_exception(error)
    else:
        future.set_result(result)


def _call_done(done: Done, result: Any, error: BaseException | None) -> None:
    try:
        done(result, error)
    except Exception:  # a closed loop (the app stopped): the answer has nobody to go to
        pass


class Bulkheads:
    """The bulkhead of each rule set (and of each stream binding), created on first use."""

    def __init__(self, workers: int, max_queue: int, max_wait_s: float) -> None:
        self.workers, self.max_queue, self.max_wait_s = workers, max_queue, max_wait_s
        self._by_name: dict[str, Bulkhead] = {}
        self._lock = threading.Lock()

    def of(self, name: str) -> Bulkhead:
        found = self._by_name.get(name)
        if found is not None:
            return found
        with self._lock:
            return self._by_name.setdefault(name, Bulkhead(name, self.workers, self.max_queue, self.max_wait_s))

    def stats(self) -> dict[str, dict[str, Any]]:
        return {name: b.stats() for name, b in list(self._by_name.items())}
