"""Small helpers shared by the ROS tests (bounded waits only)."""

from __future__ import annotations

import time


def wait_for(cond, timeout_s: float = 20.0, step: float = 0.05) -> bool:
    """Poll ``cond`` until true or ``timeout_s`` passes; returns its last value."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(step)
    return bool(cond())
