"""End to end: ``printeps demo`` headless on its own ROS_DOMAIN_ID — real DB, JVM, ROS nodes, REST."""

from __future__ import annotations

import os

import pytest

pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (ros/install.sh)")
pytest.importorskip("printeps_interfaces", reason="printeps_interfaces not built (ros/install.sh)")

from gateway.config import Settings  # noqa: E402
from gateway.demo import run_demo  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]  # the whole demo end to end


def test_teahouse_reception_end_to_end(tmp_path, monkeypatch) -> None:
    monkeypatch.delenv("MONGO_URI", raising=False)
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    lines: list[str] = []
    summary = run_demo(Settings(data_dir=str(tmp_path)), headless=True, speed=4.0,
                       domain_id=1 + (os.getpid() + 57) % 100, out=lines.append)
    calls = [(c["service"], c.get("text") or c.get("location") or c.get("name")) for c in summary["robot_calls"]]
    reception = [
        ("move_to", "entrance"), ("speak", "Welcome. Two seats?"), ("gesture", "bow"), ("move_to", "table for two"),
        ("move_to", "entrance"), ("speak", "Welcome. Three seats?"), ("gesture", "bow"), ("move_to", "table for four"),
    ]
    clearing = [("move_to", "table2"), ("move_to", "counter")]  # the clear_table workflow's robot steps
    ordering = [("speak", "2 green teas, certainly. Is that right?"),  # customers at table 1, by voice
                ("speak", "Thank you. Your green teas will be ready soon."),
                ("speak", "How many cups of coffee?"),  # the second one forgot the count
                ("speak", "3 coffees, certainly. Is that right?"),
                ("speak", "Thank you. Your coffees will be ready soon.")]
    assert [c for c in calls if c in ordering] == ordering, "\n".join(lines)
    assert [(o["drink"], o["cups"]) for o in summary["orders"]] == [("green tea", 2), ("coffee", 3)]
    assert all(c.get("audio", "").endswith(".wav") for c in summary["robot_calls"] if c["service"] == "speak")
    calls = [c for c in calls if c not in ordering]
    assert [c for c in calls if c not in clearing] == reception, "\n".join(lines)
    assert [c for c in calls if c in clearing] == clearing, "\n".join(lines)
    assert summary["detections"] == 2 and summary["failed"] == 0 and summary["rejected"] == 0
    assert summary["tables_cleared"] == ["table2"], "\n".join(lines)
    assert summary["store"]["status"] == "ok" and summary["store"]["buffered"] == 0
    text = "\n".join(lines)
    assert "detected entering customers: g1a, g1b" in text and "Summary" in text
    assert "the party at table2 has left" in text
