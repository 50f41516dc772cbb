"""Background work (rule compiles, explain queries, build jobs, the start-up warm-up) at a lower CPU
priority than serving.

Why: a gateway serves fires while it compiles. On the 2 cores it targets, a deploy's or an explain
prebuild's compile threads and the fire thread take turns on the cores, and the scheduler hands
each a slice of milliseconds: a 100-rule set's fires (p50 0.07 ms) had a p99 of 4–8 ms while the
explain queries of its last deploy compiled in the background, and 0.2–0.8 ms once that thread ran
at nice 10 (docs/benchmarks.md, "Background work at a lower priority"). A lower priority costs
nothing on an idle machine: it only decides who waits when both want a core.

Off by default (``engine.background_nice: 0``): on a machine saturated by other processes (the
test suite's workers, a browser, the database), a lowered thread waits for a core for long
stretches, also while it holds the GIL or runs a build an author is waiting for (a workbench test
waited 60 s for a held build's first stage). Turn it on where the gateway has its cores to itself.

How: Linux schedules each thread on its own, so a thread can lower its own priority
(``setpriority`` on its thread id; raising it back would need privileges, so only threads that
only ever do background work are lowered, once, when they start). The Java work such a thread
asks for runs on that same thread (JPype calls Java on the caller's thread), so it is lowered too.
Elsewhere (not Linux) nothing changes.
"""

from __future__ import annotations

import logging
import os
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

log = logging.getLogger(__name__)

#: How much lower (nice steps) background threads run; ``engine.background_nice`` (0, the default: as serving).
_nice = 0


def configure(nice: int) -> None:
    """Set how much lower background threads started from now on run (the engine calls this with
    ``engine.background_nice``)."""
    global _nice
    _nice = max(0, int(nice))


def lower_this_thread() -> None:
    """Run the calling thread the configured steps below the process's main thread (a pool's
    ``initializer``, or the first thing a background thread does). A thread inherits its
    creator's priority, so one started by a background thread is there already and stays (steps
    do not add up). Best effort: an error is logged, not raised."""
    if _nice <= 0 or not sys.platform.startswith("linux"):
        return
    tid = threading.get_native_id()
    try:
        target = min(19, os.getpriority(os.PRIO_PROCESS, threading.main_thread().native_id) + _nice)
        if os.getpriority(os.PRIO_PROCESS, tid) < target:
            os.setpriority(os.PRIO_PROCESS, tid, target)
    except OSError:
        log.debug("could not lower the priority of thread %s", tid, exc_info=True)


def background_pool(workers: int, name: str) -> ThreadPoolExecutor:
    """A thread pool whose threads run below serving (:func:`lower_this_thread` as they start)."""
    return ThreadPoolExecutor(max_workers=workers, thread_name_prefix=name, initializer=lower_this_thread)


def thread_nice() -> int:
    """The calling thread's nice value (for tests and diagnostics)."""
    return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
