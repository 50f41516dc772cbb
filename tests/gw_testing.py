"""Helpers for tests that need a gateway: stores on the shared test server, gateways built through
the one composition root (:func:`gateway.app.build_gateway`)."""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import itertools
import os
import time
from pathlib import Path
from typing import Any, Callable, Coroutine, TypeVar

T = TypeVar("T")

_databases = itertools.count(1)


#: The JVM option given to the gateway processes the tests start (see :func:`short_lived_jvm`).
SHORT_LIVED_JVM = "-XX:TieredStopAtLevel=1"


def short_lived_jvm(env: dict[str, str]) -> dict[str, str]:
    """``env`` for a gateway process a test starts (``printeps serve``, ``ros_launch``, a CLI
    command), with its JVM on the C1 compiler only: ``SHORT_LIVED_JVM`` appended to any
    ``PRINTEPS_JVM_OPTIONS`` in ``env``.

    Why: such a process lives seconds and serves a handful of requests, so what C2's threads spend
    optimising never pays back: 9-18% less CPU for whole cluster files and the export/import and
    ROS-launcher tests (docs/operations.md, "Where the suite's time goes", fourth pass). Only these
    processes: the pytest workers' own JVMs run a whole file's workload and keep C2, which is why
    this is not an environment variable of the run."""
    return {**env, "PRINTEPS_JVM_OPTIONS": f"{env.get('PRINTEPS_JVM_OPTIONS', '')} {SHORT_LIVED_JVM}".strip()}


def run_async(coro: Coroutine[Any, Any, T]) -> T:
    """``asyncio.run(coro)`` on a thread of its own: the session's browser (Playwright's sync API)
    keeps an event loop running on the main thread once a browser test has run in this process
    (with pytest-xdist any test file may come after one), and asyncio.run refuses to start there."""
    with concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="test-async") as pool:
        return pool.submit(asyncio.run, coro).result()


def wait_for(cond: Callable[[], object], timeout_s: float = 30.0, step: float = 0.05) -> bool:
    """True as soon as ``cond()`` is, False if it is still not after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(step)
    return bool(cond())


def open_test_store(mongo, folder: Path, name: str | None = None):
    """An InformationState on its own database of the shared server, journalling under ``folder``."""
    from gateway.store.store import InformationState

    database = name or f"t{os.getpid()}_{next(_databases)}"
    return InformationState(mongo.uri, database, Path(folder) / "journal", backend="embedded", timeout_ms=1000,
                            retry_interval_s=0.2)


@contextlib.contextmanager
def built_gateway(settings, mongo, folder: Path, **options):
    """``build_gateway`` (the one composition root) over a fresh database of the shared server;
    closes the gateway and its store afterwards."""
    from gateway.app import build_gateway

    if "explain_prebuild" not in settings.engine.model_fields_set:
        # every test gateway would otherwise compile the explain queries of each rule set it loads
        # or deploys in the background (seconds of a core each); the tests of that turn it on
        settings.engine.explain_prebuild = False
    store = open_test_store(mongo, folder)
    try:
        gateway = build_gateway(settings, store=store, **{"ros": False, "warm_up": False, **options})
        try:
            yield gateway
        finally:
            gateway.close()
    finally:
        store.close()


def hold_build(monkeypatch, engine, comment: str, stage: str = "compile"):
    """Hold the real build of the deploy with ``comment`` at its first report of ``stage`` until
    the returned event is set: a test hook on the real engine (the build, its progress, its cancel
    and the gateway's answers are all real), so a test's steps never race the build's own pace on
    a loaded machine or with a warm compile cache. The job's progress reporter runs first, so the
    job is seen at that stage and a cancel asked for meanwhile is heard at the next report."""
    import threading

    release = threading.Event()
    deploy = engine.deploy

    def held(name, files, *args, on_progress=None, **kwargs):
        def progress(done: int, total: int, reported: str) -> None:
            if on_progress is not None:
                on_progress(done, total, reported)
            if reported == stage and kwargs.get("comment") == comment:
                release.wait(120)
        return deploy(name, files, *args, on_progress=progress, **kwargs)

    monkeypatch.setattr(engine, "deploy", held)
    return release


#: A fact type and a rule whose then-part waits until the test creates the fact's gate file (having
#: created its "started" file first): a test knows by a condition, not a sleep, that a fire is
#: running, and decides when it ends (tests of bulkheads and fire lanes). Put a package line before it.
GATED_JOB_DRL = """declare Job
    id : String
    started : String
    gate : String
end

rule "Wait for the gate"
when
    $j : Job()
then
    // only for a test's gate (an absolute path): the warm-up of a deploy fires made-up facts
    if ($j.getGate() != null && $j.getGate().startsWith("/")) {
        try { new java.io.File($j.getStarted()).createNewFile(); } catch (Exception e) { }
        long deadline = System.currentTimeMillis() + 120000;
        while (!new java.io.File($j.getGate()).exists() && System.currentTimeMillis() < deadline) {
            try { Thread.sleep(5); } catch (InterruptedException e) { }
        }
    }
end
"""


class Gate:
    """One gated fire's "started" and gate files (its facts for :data:`GATED_JOB_DRL`)."""

    def __init__(self, folder: Path, name: str) -> None:
        self.started = folder / f"{name}.started"
        self.gate = folder / f"{name}.gate"

    def facts(self) -> list[dict[str, Any]]:
        return [{"type": "Job", "id": self.gate.stem, "started": str(self.started), "gate": str(self.gate)}]

    def open(self) -> None:
        self.gate.touch()
