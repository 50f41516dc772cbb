"""Unit tests of the plain-Python core: readings, entry detection on the stream engine, scenario
files, dispatcher policy, robot positions."""

from __future__ import annotations

import math

import pytest

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


ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]


def _detected(readings: list[dict]) -> list[str]:
    """The customers the shipped CustomerDetectionQuery detects in these readings, mapped to RDF by
    the shipped entrance mapping — the path a ROS entrance message takes in the gateway."""
    import yaml

    from gateway.config import StreamSettings
    from gateway.rdf.mapping import Mapper, node_map_from_spec
    from gateway.stream.engine import StreamEngine

    mapper = Mapper({"entrance": node_map_from_spec(yaml.safe_load((ROOT / "ontology" / "mappings" / "entrance.yaml").read_text()))})
    engine = StreamEngine(StreamSettings(queries_dir=None))
    engine.register((ROOT / "ontology" / "queries" / "customer_detection.rq").read_text())  # 3.3 m, from the ontology
    seen: list[str] = []
    engine.subscribe(lambda e: seen.extend(r["s"].rsplit("/", 1)[-1] for r in e.get("rows", ())
                                           if e["kind"] == "result"))
    for r in readings:
        ts = int(round(r["stamp"] * 1000))
        engine.push("http://printeps.org/cafe/entrance", ts, mapper.map(r, ts, "entrance"))
    return seen


def _readings(distances, rate=1.0, cid="c1"):
    return [{"id": f"e{i}", "stamp": 100 + i / rate, "number_of_customers": 1,
             "customers": [{"id": cid, "distance": d, "age": 30, "gender": "male"}]} for i, d in enumerate(distances)]


def test_entry_detection_follows_the_published_query() -> None:
    assert "c1" in _detected(_readings([5.0, 4.0, 3.0, 2.0, 1.8, 1.8]))
    assert not _detected(_readings([4.5] * 8))                     # passing by
    assert not _detected(_readings([1.0, 2.0, 3.0, 4.0, 5.0]))     # leaving
    assert not _detected(_readings([9.0, 8.0, 7.0, 6.0, 5.5]))     # approaching, still beyond the entrance


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
    s = load_scenario(ROOT / "scenarios" / "teahouse-reception.yaml")
    assert s.distance_to_entrance == 3.3  # as in the ontology the query binds it from
    assert set(_detected(list(s.readings()))) == {"g1a", "g1b", "g3a", "g3b", "g3c"}


def test_dispatcher_retries_a_bounded_number_of_times() -> None:
    calls = []

    def caller(service, type_name, params, timeout_s):
        calls.append(service)
        return "timeout", "no answer"

    d = ActionDispatcher(caller, {"pepper": "/pepper"}, retries=2, retry_pause_s=0)
    out = d.dispatch({"module": "say", "params": {"robot": "pepper", "text": "hi"}})
    assert out["status"] == "timeout" and out["attempts"] == 3 and calls == ["/pepper/speak"] * 3
    assert d.dispatch({"module": "say", "params": {"robot": "nao", "text": "x"}})["status"] == "unsupported"
    assert "notify_staff" in d.dispatch({"module": "notify_staff", "params": {}})["message"]
    assert len(calls) == 3


def test_robot_positions_follow_successful_moves() -> None:
    from gateway.ros.robots import RobotStates

    robots = RobotStates({"pepper": "counter"})
    assert robots.facts() == [{"type": "Robot", "id": "pepper", "position": "counter"}]
    robots.on_outcome({"status": "timeout", "action": {"module": "move", "params": {"robot": "pepper", "location": "entrance"}}})
    assert robots.position("pepper") == "counter"
    robots.on_outcome({"status": "ok", "action": {"module": "move", "params": {"robot": "pepper", "location": "entrance"}}})
    assert robots.position("pepper") == "entrance"
