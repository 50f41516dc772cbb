"""Small helpers shared by the ROS tests (bounded waits only)."""

from __future__ import annotations

import gw_testing


def wait_for(cond, timeout_s: float = 20.0, step: float = 0.05) -> bool:
    """The shared bounded wait (:func:`gw_testing.wait_for`), with the ROS tests' default of 20 s."""
    return gw_testing.wait_for(cond, timeout_s, step)
