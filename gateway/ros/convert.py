"""ROS messages ↔ plain dicts, for any message or service type named ``pkg/msg/Name`` / ``pkg/srv/Name``.

Why generic: the gateway subscribes to whatever topics the configuration names and calls whatever
robot services the dispatcher or a workflow asks for; the types come from rosidl at run time
(``get_fields_and_field_types``), so no code is written per message type. The core never sees a
ROS type: only the dicts these functions make.
"""

from __future__ import annotations

import importlib
import math
from typing import Any


class ConversionError(ValueError):
    """A value that does not fit a message field; the message names the field."""


def import_type(name: str) -> Any:
    """``pkg/srv/Name`` or ``pkg/msg/Name`` -> the generated Python class (ValueError if unknown)."""
    parts = name.split("/")
    if len(parts) != 3 or parts[1] not in ("msg", "srv", "action"):
        raise ValueError(f"type {name!r}: expected pkg/msg/Name or pkg/srv/Name")
    package, kind, cls = parts
    try:
        return getattr(importlib.import_module(f"{package}.{kind}"), cls)
    except (ImportError, AttributeError):
        raise ValueError(f"type {name!r} is not installed (no {package}.{kind}.{cls})") from None


def describe(type_name: str) -> dict[str, str]:
    """The fields of a message type and their rosidl types (``{"customers": "sequence<pkg/Customer>"}``)."""
    return dict(import_type(type_name).get_fields_and_field_types())


def fill(message: Any, values: dict[str, Any], where: str, *, strict: bool = True) -> Any:
    """Set fields of a ROS message from a dict. Unknown fields are an error naming the field
    (``strict``) or left out (the dispatcher: rule actions may carry extra parameters)."""
    fields = message.get_fields_and_field_types()
    for key, value in values.items():
        if key not in fields:
            if not strict:
                continue
            raise ConversionError(f"{where}: {type(message).__name__} has no field {key!r} "
                                  f"(fields: {', '.join(fields)})")
        kind = fields[key]
        try:
            if kind in ("float", "double"):
                value = float(value)
            elif kind.startswith(("int", "uint")) or kind in ("byte", "octet"):
                value = int(value)
            elif kind.startswith("string"):
                value = str(value)
            elif kind == "boolean":
                value = bool(value)
            elif isinstance(value, dict):
                value = fill(getattr(message, key), value, f"{where}.{key}", strict=strict)
            setattr(message, key, value)
        except (TypeError, ValueError, AssertionError) as exc:
            raise ConversionError(f"{where}.{key}: cannot set {value!r} as {kind}: {exc}") from None
    return message


def to_dict(message: Any) -> Any:
    """A ROS message as plain JSON-like data (nested messages, sequences and arrays included)."""
    if hasattr(message, "get_fields_and_field_types"):
        return {k: to_dict(getattr(message, k)) for k in message.get_fields_and_field_types()}
    if isinstance(message, (list, tuple)):
        return [to_dict(v) for v in message]
    if hasattr(message, "tolist"):
        return message.tolist()
    return message


def stamp_ms(value: Any) -> int | None:
    """A ``builtin_interfaces/Time`` (as a dict or message) or seconds as epoch milliseconds;
    None when absent or zero (the receive time is used then)."""
    if isinstance(value, dict):
        seconds = float(value.get("sec", 0)) + float(value.get("nanosec", 0)) / 1e9
    elif hasattr(value, "sec"):
        seconds = value.sec + value.nanosec / 1e9
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        seconds = float(value)
    else:
        return None
    if not math.isfinite(seconds) or seconds <= 0:
        return None
    return int(round(seconds * 1000))


def float_to_stamp(t: float) -> Any:
    from builtin_interfaces.msg import Time

    sec = int(math.floor(t))
    return Time(sec=sec, nanosec=min(999_999_999, int(round((t - sec) * 1e9))))


def dict_to_entrance(d: dict[str, Any]) -> Any:
    """A scenario reading as an Entrance message (the sensor simulator's)."""
    from printeps_interfaces.msg import Customer, Entrance

    customers = [Customer(id=str(c["id"]), distance=float(c["distance"]), age=int(c.get("age", -1)),
                          age_range_min=int(c.get("age_range_min", -1)), age_range_max=int(c.get("age_range_max", -1)),
                          gender=str(c.get("gender", ""))) for c in d.get("customers", [])]
    return Entrance(id=str(d["id"]), number_of_customers=int(d.get("number_of_customers", len(customers))),
                    customers=customers, stamp=float_to_stamp(float(d["stamp"])))
