"""Where each robot is: the ``robots`` facts a rule binding can ask for (``context: [robots]``).

Why kept by the gateway: the reception rules decide whether Pepper must first come to the
entrance (``Robot(position == $e.id)``); the robot's position is what its last successful ``move``
made it, starting from ``ros.robot_start``. Plain Python: the dispatcher reports outcomes here.
"""

from __future__ import annotations

import threading
from typing import Any


class RobotStates:
    """Robot name → position; ``facts()`` gives one ``Robot`` fact per robot."""

    def __init__(self, start: dict[str, str]) -> None:
        self._positions = dict(start)
        self._lock = threading.Lock()

    def facts(self) -> list[dict[str, Any]]:
        with self._lock:
            return [{"type": "Robot", "id": robot, "position": position} for robot, position in self._positions.items()]

    def position(self, robot: str) -> str | None:
        with self._lock:
            return self._positions.get(robot)

    def on_outcome(self, outcome: dict[str, Any]) -> None:
        """A dispatcher listener: a robot that moved is where it went."""
        action = outcome.get("action") or {}
        params = action.get("params") or {}
        if outcome.get("status") == "ok" and action.get("module") == "move" and params.get("robot"):
            with self._lock:
                self._positions[str(params["robot"])] = str(params.get("location") or "")
