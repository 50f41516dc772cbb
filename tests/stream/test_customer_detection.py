"""The papers' CustomerDetectionQuery, as published (only ?distance_to_entrance bound from the
ontology: 3.3 m), on synthetic entrance scenarios with hand-worked expectations.

Window semantics: RANGE 3s STEP 1s closes at every whole second E and holds readings with
E-3000 <= ts < E. COUNT and AVG run over (later, earlier) pairs of a person's readings whose
distance shrank by more than 0.1 m.
"""

from __future__ import annotations

from decimal import Decimal

import pytest
from csparql_scenarios import (
    CUSTOMER_QUERY,
    approaching,
    detections,
    leaving,
    messages,
    nonempty,
    replay,
    walking_past,
)

from gateway.config import StreamSettings
from gateway.stream import StreamEngine


def _engine(settings: StreamSettings, fast: bool) -> StreamEngine:
    engine = StreamEngine(settings.model_copy(update={"fast_path": fast}))
    engine.register(CUSTOMER_QUERY)
    return engine


@pytest.mark.parametrize("fast", [True, False], ids=["fast-path", "pyoxigraph"])
def test_papers_rate_one_reading_per_second(settings, fast):
    # Readings at 500, 1500, … ms. c1 approaches from 4.0 m at 0.3 m/s; c2 walks past at 2.5 m;
    # c3 leaves from 1.0 m; c4 drifts 0.05 m/s closer (differences 0.05 and exactly 0.1: not > 0.1).
    tracks = {"c1": approaching(4.0, 0.3), "c2": walking_past(2.5), "c3": leaving(1.0, 0.3),
              "c4": approaching(2.0, 0.05)}
    engine = _engine(settings, fast)
    events = replay(engine, messages(tracks, hz=1, seconds=10, t0_ms=500))
    found = detections(events)
    # Window ending E holds readings k = E/1000-3 … E/1000-1 (ts = 500 + 1000k).
    # Window ending 3000: c1 at 4.0, 3.7, 3.4 -> 3 pairs, AVG(distance1) = (3.7+3.4+3.4)/3 = 3.5 >= 3.3.
    # Window ending E >= 4000: readings a, a-0.3, a-0.6 -> AVG = a - 0.5 with a = 4.0 - 0.3*(E/1000-3).
    # The last window closed is 9000 (the reading at 9500 closes it; nothing closes 10000).
    assert sorted(found) == [4000, 5000, 6000, 7000, 8000, 9000]
    for end, ids in found.items():
        assert ids == {"c1"}
    # every window is reported; those without a detection have no rows
    assert [e["window"]["end"] for e in events] == list(range(1000, 10_000, 1000))
    for event in nonempty(events):
        (row,) = event["rows"]
        a = Decimal("4.0") - Decimal("0.3") * (event["window"]["end"] // 1000 - 3)
        assert row["cnt"] == 3
        assert Decimal(str(row["distance"])) == a - Decimal("0.5")
        assert event["path"] == ("fast" if fast else "oxigraph")


def test_thirty_hertz(settings):
    # c1 approaches from 5.0 m at 0.5 m/s: every reading in a window ending E >= 7000 is < 3.3 m
    # (5.0 - 0.5*(E/1000 - 3) < 3.3), so it must be detected there; in windows ending <= 3000 every
    # reading is >= 3.5 m, so it must not. c2 walks past with +-0.04 m noise (differences <= 0.08),
    # c3 leaves: neither is ever detected.
    tracks = {"c1": approaching(5.0, 0.5), "c2": walking_past(2.0, noise=0.04, seed=7),
              "c3": leaving(0.8, 0.5)}
    engine = _engine(settings, fast=True)
    events = replay(engine, messages(tracks, hz=30, seconds=8.5), flush_ms=9000)
    found = detections(events)
    for end in range(1000, 9001, 1000):
        if end >= 7000:
            assert found.get(end) == {"c1"}, end
        elif end <= 3000:
            assert end not in found, end
    assert all(ids <= {"c1"} for ids in found.values())
    stats = engine.queries()[0]["stats"]
    assert stats["fast"] == stats["windows"] and stats["fallbacks"] == 0


def test_both_paths_agree_at_thirty_hertz(settings):
    tracks = {f"c{i}": approaching(4.5 - 0.1 * i, 0.4) for i in range(3)}
    tracks["p"] = walking_past(2.0, noise=0.06, seed=3)  # noise above the 0.1 threshold: see docs
    msgs = messages(tracks, hz=30, seconds=4.2)
    fast = replay(_engine(settings, True), msgs, flush_ms=5000)
    slow = replay(_engine(settings, False), msgs, flush_ms=5000)
    strip = lambda evs: [(e["window"], sorted(map(sorted, (r.items() for r in e["rows"])))) for e in evs]  # noqa: E731
    assert strip(fast) == strip(slow)
    assert fast, "the scenario must produce detections"


def test_replay_is_deterministic(settings):
    msgs = messages({"c1": approaching(4.0, 0.3), "c2": walking_past(2.0, 0.05, 1)}, hz=10, seconds=8)
    first = replay(_engine(settings, True), msgs)
    second = replay(_engine(settings, True), msgs)
    drop_timing = lambda evs: [{k: v for k, v in e.items() if k != "eval_ms"} for e in evs]  # noqa: E731
    assert drop_timing(first) == drop_timing(second)
