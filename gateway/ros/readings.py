"""Check entrance readings before anything else sees them: bad sensor values get a clear error.

Why here and not in the stream code: a reading is rejected as a whole (and recorded as rejected),
so one NaN or a thousand phantom customers can never reach the window, the rules or the robot.
"""

from __future__ import annotations

import math
from typing import Any


class ReadingError(ValueError):
    """A reading that cannot be used; ``field`` says where (e.g. ``customers[2].distance``)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message

    def to_dict(self) -> dict[str, str]:
        return {"field": self.field, "message": self.message}


def _number(value: Any, field: str, *, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ReadingError(field, f"{value!r} is not a number")
    if not math.isfinite(value):
        raise ReadingError(field, f"{value!r} is not a finite number")
    if value < low or value > high:
        raise ReadingError(field, f"{value!r} is out of range [{low:g}, {high:g}]")
    return float(value)


def validate_entrance(reading: dict[str, Any], *, max_customers: int = 100, max_distance_m: float = 20.0) -> dict:
    """Return the reading unchanged if usable, else raise ReadingError naming the bad field."""
    if not str(reading.get("id", "")).strip():
        raise ReadingError("id", "is empty")
    customers = reading.get("customers") or []
    n = reading.get("number_of_customers", len(customers))
    if isinstance(n, bool) or not isinstance(n, int) or n < 0 or n > max_customers:
        raise ReadingError("number_of_customers", f"{n!r} is out of range [0, {max_customers}]")
    if len(customers) > max_customers:
        raise ReadingError("customers", f"{len(customers)} customers is more than the limit {max_customers}")
    seen = set()
    for i, c in enumerate(customers):
        where = f"customers[{i}]"
        cid = str(c.get("id", "")).strip()
        if not cid:
            raise ReadingError(f"{where}.id", "is empty")
        if cid in seen:
            raise ReadingError(f"{where}.id", f"{cid!r} appears twice in one reading")
        seen.add(cid)
        _number(c.get("distance"), f"{where}.distance", low=0.0, high=max_distance_m)
        age = c.get("age", -1)
        if isinstance(age, bool) or not isinstance(age, int) or age < -1 or age > 130:
            raise ReadingError(f"{where}.age", f"{age!r} is out of range [-1 (unknown), 130]")
    stamp = reading.get("stamp")
    if stamp is not None and not isinstance(stamp, dict):  # a builtin_interfaces/Time is checked by the ingress
        _number(stamp, "stamp", low=0.0, high=1e11)
    return reading
