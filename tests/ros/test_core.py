"""Unit tests of the plain-Python core: readings, detector, scenario files, dispatcher policy."""

from __future__ import annotations

import math

import pytest

from gateway.ros.detector import EntryDetector
from gateway.ros.dispatcher import ActionDispatcher
from gateway.ros.readings import ReadingError, validate_entrance
from gateway.ros.scenario import ScenarioError, load_scenario

GOOD = {"id": "e1", "number_of_customers": 1, "customers": [{"id": "c1", "distance": 2.0, "age": 30}], "stamp": 1.0}


@pytest.mark.parametrize("change, field", [
    ({"customers": [{"id": "c1", "distance": -0.5, "age": 30}]}, "customers[0].distance"),
    ({"customers": [{"id": "c1", "distance": math.nan, "age": 30}]}, "customers[0].distance"),
    ({"customers": [{"id": "c1", "distance": math.inf, "age": 30}]}, "customers[0].distance"),
    ({"customers": [{"id": "c1", "distance": 500.0, "age": 30}]}, "customers[0].distance"),
    ({"customers": [{"id": f"c{i}", "distance": 2.0} for i in range(1000)], "number_of_customers": 1000},
     "number_of_customers"),
    ({"customers": [{"id": f"c{i}", "distance": 2.0} for i in range(1000)], "number_of_customers": 3}, "customers"),
    ({"customers": [{"id": "c1", "distance": 2.0, "age": 400}]}, "customers[0].age"),
    ({"customers": [{"id": "", "distance": 2.0}]}, "customers[0].id"),
    ({"customers": [{"id": "a", "distance": 2.0}, {"id": "a", "distance": 2.0}]}, "customers[1].id"),
    ({"id": ""}, "id"),
])
def test_bad_readings_name_the_field(change, field) -> None:
    with pytest.raises(ReadingError) as err:
        validate_entrance({**GOOD, **change})
    assert err.value.field == field and field in str(err.value)


def test_good_reading_passes() -> None:
    assert validate_entrance(dict(GOOD))["id"] == "e1"


def _readings(distances, rate=1.0, cid="c1"):
    return [{"id": f"e{i}", "stamp": i / rate, "customers": [{"id": cid, "distance": d}]}
            for i, d in enumerate(distances)]


def test_detector_follows_the_published_query() -> None:
    det = EntryDetector()
    events = [e for r in _readings([5.0, 4.0, 3.0, 2.0, 1.8]) for e in det.push(r)]
    assert events and events[0]["s"] == "c1" and events[0]["distance"] < 3.3 and events[0]["cnt"] > 1
    passing = EntryDetector()
    assert not [e for r in _readings([4.5] * 8) for e in passing.push(r)]
    leaving = EntryDetector()
    assert not [e for r in _readings([1.0, 2.0, 3.0, 4.0, 5.0]) for e in leaving.push(r)]
    far = EntryDetector()  # approaching but still beyond ?distance_to_entrance
    assert not [e for r in _readings([9.0, 8.0, 7.0, 6.0]) for e in far.push(r)]


def test_scenario_errors_have_file_line_column_and_field(tmp_path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("name: x\nevents:\n  - at: 0\n    people: [{id: a}]\n    from: -3\n    to: 1\n    duration: 2\n")
    with pytest.raises(ScenarioError, match=r"bad.yaml:5:11: events.0.from: Input should be greater"):
        load_scenario(bad)
    syntax = tmp_path / "syntax.yaml"
    syntax.write_text("name: [x\n")
    with pytest.raises(ScenarioError, match=r"syntax.yaml:2:1: YAML syntax error"):
        load_scenario(syntax)


def test_the_shipped_scenario_detects_both_groups_only() -> None:
    from pathlib import Path
    s = load_scenario(Path(__file__).resolve().parents[2] / "scenarios" / "teahouse-reception.yaml")
    det = EntryDetector(distance_to_entrance=s.distance_to_entrance)
    ids = {e["s"] for r in s.readings() for e in det.push(r)}
    assert ids == {"g1a", "g1b", "g3a", "g3b", "g3c"}


def test_dispatcher_retries_a_bounded_number_of_times() -> None:
    calls = []

    def caller(service, kind, params, timeout_s):
        calls.append(service)
        return "timeout", "no answer"

    d = ActionDispatcher(caller, {"pepper": "/pepper"}, retries=2, retry_pause_s=0)
    out = d.dispatch({"module": "say", "params": {"robot": "pepper", "text": "hi"}})
    assert out["status"] == "timeout" and out["attempts"] == 3 and calls == ["/pepper/speak"] * 3
    assert d.dispatch({"module": "say", "params": {"robot": "nao", "text": "x"}})["status"] == "unsupported"
    assert "notify_staff" in d.dispatch({"module": "notify_staff", "params": {}})["message"]
    assert len(calls) == 3
