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

The hand-off is the cheapest measured (docs/benchmarks.md): a C ``SimpleQueue`` the workers block
on, and for an asyncio caller the answers handed back to the loop in batches (one
``call_soon_threadsafe`` for the answers that finish while the loop is busy, :class:`_Inbox`).
"""

from __future__ import annotations

import asyncio
import collections
import math
import queue
import threading
import time
import weakref
from typing import Any, Callable

from gateway.engine.errors import Overloaded

Done = Callable[[Any, BaseException | None], None]

#: Weight of the newest fire in a rule set's mean fire time (the wait estimate).
SMOOTHING = 0.2


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
        self.mean_s = 0.0
        self.refused = {"queue_full": 0, "waited": 0}

    # -- submitting ---------------------------------------------------------------------------------
    def submit(self, fn: Callable[[], Any], done: Done) -> None:
        """Queue ``fn`` for a worker, which calls ``done(result, error)`` when it ran (or was refused
        for waiting too long); raises :class:`Overloaded` at once when it would not be served in time."""
        with self._lock:
            if self.waiting >= self.max_queue:
                self.refused["queue_full"] += 1
                raise self._refusal("queue_full", self._expected_wait())
            expected = self._expected_wait()
            if expected > self.max_wait_s:
                self.refused["waited"] += 1
                raise self._refusal("waited", expected)
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
            self.mean_s = elapsed if self.mean_s == 0.0 else self.mean_s + SMOOTHING * (elapsed - self.mean_s)
        _call_done(done, result, error)

    # -- limits -------------------------------------------------------------------------------------
    def _expected_wait(self) -> float:
        """How long a fire submitted now would wait, by the recent mean fire time (under the lock)."""
        return self.mean_s * (self.waiting + self.running) / self.workers

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
        with self._lock:
            return {"waiting": self.waiting, "running": self.running, "threads": self.threads,
                    "mean_fire_ms": round(self.mean_s * 1000, 3), "refused": dict(self.refused)}


class _Inbox:
    """The answers of every bulkhead for one event loop, settled there in batches.

    Why: each ``call_soon_threadsafe`` writes to the loop's wake-up pipe (a system call, and a
    wake-up the loop reads back). Answers that finish while a drain is already scheduled join it,
    so a busy loop is woken once for them all instead of once per fire."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._answers: collections.deque[tuple[asyncio.Future[Any], Any, BaseException | None]] = collections.deque()
        self._scheduled = False

    def deliver(self, future: asyncio.Future[Any], result: Any, error: BaseException | None) -> None:
        """From a worker: settle ``future`` on the loop (raises RuntimeError once the loop closed)."""
        self._answers.append((future, result, error))
        if not self._scheduled:  # two workers may both schedule a drain: the second finds it done
            self._scheduled = True
            try:
                self._loop.call_soon_threadsafe(self._drain)
            except RuntimeError:
                self._scheduled = False
                raise

    def _drain(self) -> None:
        self._scheduled = False  # first: an answer added from now on schedules the next drain
        answers = self._answers
        while answers:
            _settle(*answers.popleft())


_inboxes: weakref.WeakKeyDictionary[asyncio.AbstractEventLoop, _Inbox] = weakref.WeakKeyDictionary()
_inboxes_lock = threading.Lock()


def _inbox_of(loop: asyncio.AbstractEventLoop) -> _Inbox:
    found = _inboxes.get(loop)
    if found is None:
        with _inboxes_lock:
            found = _inboxes.setdefault(loop, _Inbox(loop))
    return found


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
