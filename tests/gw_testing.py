"""Helpers for tests that need a gateway: stores on the shared test server, gateways built through
the one composition root (:func:`gateway.app.build_gateway`)."""

from __future__ import annotations

import contextlib
import itertools
import os
import time
from pathlib import Path
from typing import Callable

_databases = itertools.count(1)


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

    store = open_test_store(mongo, folder)
    try:
        gateway = build_gateway(settings, store=store, **{"ros": False, "warm_up": False, **options})
        try:
            yield gateway
        finally:
            gateway.close()
    finally:
        store.close()
