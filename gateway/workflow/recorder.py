"""Where runs are recorded: the Information State when the gateway has one, memory otherwise.

Why injected: the executor must not depend on MongoDB. The gateway passes a recorder that writes to
the Information State (``gateway.store``); tests pass :class:`MemoryRecorder`. A broken recorder
never breaks a run: the executor logs and goes on.
"""

from __future__ import annotations

import threading
from collections import deque
from typing import Any, Callable, Protocol


class Recorder(Protocol):
    def record(self, kind: str, payload: dict[str, Any]) -> None:
        """Store one event: ``workflow_run_started``, ``workflow_step``, ``workflow_run_finished``."""
        ...


class MemoryRecorder:
    """Keeps the last ``limit`` events in memory."""

    def __init__(self, limit: int = 10_000) -> None:
        self.events: deque[tuple[str, dict[str, Any]]] = deque(maxlen=limit)
        self._lock = threading.Lock()

    def record(self, kind: str, payload: dict[str, Any]) -> None:
        with self._lock:
            self.events.append((kind, payload))

    def of_kind(self, kind: str) -> list[dict[str, Any]]:
        with self._lock:
            return [p for k, p in self.events if k == kind]


class CallableRecorder:
    """Adapts any ``fn(kind, payload)`` (e.g. the Information State's ``record``) to a recorder."""

    def __init__(self, fn: Callable[[str, dict[str, Any]], Any]) -> None:
        self.fn = fn

    def record(self, kind: str, payload: dict[str, Any]) -> None:
        self.fn(kind, payload)


class FanOutRecorder:
    """Sends each event to several recorders (e.g. memory for the API + the Information State)."""

    def __init__(self, *recorders: Recorder) -> None:
        self.recorders = recorders

    def record(self, kind: str, payload: dict[str, Any]) -> None:
        for recorder in self.recorders:
            recorder.record(kind, payload)
