"""ROS messages ↔ plain dicts (the core never sees a ROS type)."""

from __future__ import annotations

import math
from typing import Any

from builtin_interfaces.msg import Time
from printeps_interfaces.msg import Customer, Entrance, EntranceSensor


def stamp_to_float(stamp: Time) -> float:
    return stamp.sec + stamp.nanosec / 1e9


def float_to_stamp(t: float) -> Time:
    sec = int(math.floor(t))
    return Time(sec=sec, nanosec=min(999_999_999, int(round((t - sec) * 1e9))))


def customer_to_dict(c: Customer) -> dict[str, Any]:
    return {"id": c.id, "distance": float(c.distance), "age": int(c.age), "age_range_min": int(c.age_range_min),
            "age_range_max": int(c.age_range_max), "gender": c.gender}


def entrance_to_dict(msg: Entrance) -> dict[str, Any]:
    stamp = stamp_to_float(msg.stamp)
    return {"id": msg.id, "number_of_customers": int(msg.number_of_customers),
            "customers": [customer_to_dict(c) for c in msg.customers], "stamp": stamp if stamp > 0 else None}


def entrance_sensor_to_dict(msg: EntranceSensor) -> dict[str, Any]:
    out = entrance_to_dict(msg.entrance)
    out.update({"sensor_id": msg.sensor_id, "location": msg.location or None,
                "distance_to_entrance": float(msg.distance_to_entrance)})
    return out


def dict_to_entrance(d: dict[str, Any]) -> Entrance:
    customers = [Customer(id=str(c["id"]), distance=float(c["distance"]), age=int(c.get("age", -1)),
                          age_range_min=int(c.get("age_range_min", -1)), age_range_max=int(c.get("age_range_max", -1)),
                          gender=str(c.get("gender", ""))) for c in d.get("customers", [])]
    return Entrance(id=str(d["id"]), number_of_customers=int(d.get("number_of_customers", len(customers))),
                    customers=customers, stamp=float_to_stamp(float(d["stamp"])))
