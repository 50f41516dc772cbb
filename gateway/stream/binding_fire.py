"""A stream binding's bulkhead: its windows fire on its own thread, at most one in flight and one waiting.

Why: a window that closes fires the binding's rule set. Run on the stream's own thread, a slow
fire would hold up every query of the stream engine (and, behind it, the ROS callbacks and the
stream posts) for as long as it runs, and a binding slower than its windows would fall ever
further behind. Here the stream thread hands the fire to the binding's thread and waits for it at
most ``streams.binding_wait_s``:

- a fire that ends in time is answered to the stream thread, which publishes its actions as
  before (in window order, with the window's other results);
- a fire that takes longer goes on by itself and publishes its actions when it ends (``late``);
- while a fire is in flight, the next window waits as the binding's one pending fire; a newer one
  replaces it (coalesced: the newest window wins), and the replaced window is reported as
  ``skipped`` (the live feed, the query's stats). So a binding never holds more than one fire in
  flight and one waiting, however slow its rule set is: it skips, it does not fall behind.

The rule is the REST bulkheads' (:mod:`gateway.engine.bulkhead`): a bounded queue (here of one,
newest first, since a newer window supersedes an older one) and a maximum wait.
"""

from __future__ import annotations

import threading
from typing import Any, Callable

Publish = Callable[[Any, BaseException | None], None]


class Job:
    """One window's fire: ``run()`` gives the result; ``publish(result, error)`` reports it late."""

    __slots__ = ("run", "publish", "skip", "done", "finished", "late", "result", "error")

    def __init__(self, run: Callable[[], Any], publish: Publish, skip: Callable[[], None]) -> None:
        self.run, self.publish, self.skip = run, publish, skip
        self.done = threading.Event()
        self.finished = False
        self.late = False
        self.result: Any = None
        self.error: BaseException | None = None


class BindingFirer:
    """The thread of one stream binding (started on first use, stopped by :meth:`close`)."""

    def __init__(self, name: str, wait_s: float) -> None:
        self.name = name
        self.wait_s = wait_s
        self._cond = threading.Condition()
        self._current: Job | None = None
        self._pending: Job | None = None
        self._thread: threading.Thread | None = None
        self._closed = False
        self.skipped = 0
        self.late = 0

    def fire(self, job: Job) -> tuple[bool, Any]:
        """``(True, result)`` when ``job`` ran in time (raises its error); ``(False, None)`` when
        it goes on, or waits, and will publish itself."""
        with self._cond:
            if self._closed:  # the binding was removed after this window was prepared
                replaced = job
                job.late = True
            elif self._current is not None:  # a fire is in flight: wait as the one pending fire
                replaced, self._pending = self._pending, job
                job.late = True  # nobody waits for it: it publishes itself
                if replaced is not None:
                    self.skipped += 1
            else:
                replaced = None
                self._current = job
                self._start()
                self._cond.notify()
        if replaced is not None:
            replaced.skip()
            return False, None
        if job.late:
            return False, None
        job.done.wait(self.wait_s)
        with self._cond:
            if not job.finished:
                job.late = True
                self.late += 1
                return False, None
        if job.error is not None:
            raise job.error
        return True, job.result

    def _start(self) -> None:
        if self._thread is None:
            self._thread = threading.Thread(target=self._work, name=f"binding-{self.name}", daemon=True)
            self._thread.start()

    def _work(self) -> None:
        while True:
            with self._cond:
                while self._current is None and not self._closed:
                    self._cond.wait()
                if self._current is None:
                    return
                job = self._current
            try:
                job.result = job.run()
            except BaseException as exc:  # handed to whoever reports the window
                job.error = exc
            with self._cond:
                job.finished = True
                late = job.late
                job.done.set()
                self._current, self._pending = self._pending, None
            if late:
                job.publish(job.result, job.error)

    def close(self) -> None:
        """Stops the thread once its fire in flight is over; a pending window is skipped."""
        with self._cond:
            self._closed = True
            pending, self._pending = self._pending, None
            self._cond.notify_all()
        if pending is not None:
            pending.skip()

    def stats(self) -> dict[str, Any]:
        with self._cond:
            return {"in_flight": self._current is not None, "pending": self._pending is not None,
                    "skipped": self.skipped, "late": self.late}
