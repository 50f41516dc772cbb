"""?distance_to_entrance comes from the ontology and follows edits of the ontology file."""

from __future__ import annotations

import os

from csparql_scenarios import CUSTOMER_QUERY, approaching, detections, messages, replay


def _set_distance(path, value: str) -> None:
    text = path.read_text(encoding="utf-8")
    old = 'printeps:distanceToEntrance "3.3"^^xsd:decimal'
    assert old in text
    path.write_text(text.replace(old, f'printeps:distanceToEntrance "{value}"^^xsd:decimal'), encoding="utf-8")
    st = path.stat()  # make sure the change is visible even on coarse mtime clocks
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))


def test_distance_is_read_from_the_ontology_and_rebound_without_restart(engine, ontology_copy):
    engine.register(CUSTOMER_QUERY)
    assert engine.query_info("CustomerDetectionQuery")["param_values"] == {
        "distance_to_entrance": '"3.3"^^<http://www.w3.org/2001/XMLSchema#decimal>'}
    track = {"c1": approaching(4.0, 0.3)}
    before = detections(replay(engine, messages(track, hz=1, seconds=10, t0_ms=500)))
    assert min(before) == 4000  # AVG 3.2 < 3.3 (see test_customer_detection)

    _set_distance(ontology_copy, "2.5")  # the Kinect was moved closer to the door
    after = detections(replay(engine, messages(track, hz=1, seconds=10, t0_ms=100_500)))
    # windows ending 100000+E hold readings a, a-0.3, a-0.6 with AVG a-0.5 < 2.5 once a < 3.0
    assert min(end for end in after if end > 100_000) == 100_000 + 7000
    assert engine.query_info("CustomerDetectionQuery")["param_values"]["distance_to_entrance"].startswith('"2.5"')


def test_a_broken_ontology_keeps_the_last_good_value(engine, ontology_copy):
    engine.register(CUSTOMER_QUERY)
    ontology_copy.write_text("this is not turtle", encoding="utf-8")
    events = replay(engine, messages({"c1": approaching(4.0, 0.3)}, hz=1, seconds=6, t0_ms=500))
    assert detections(events)  # still detecting with 3.3
    assert engine.ontology.error and "teahouse.ttl" in engine.ontology.error


def test_constant_params_and_missing_values(engine):
    body = CUSTOMER_QUERY[CUSTOMER_QUERY.index("REGISTER"):]
    engine.register("PARAM ?distance_to_entrance = 1.0\n" + body)
    assert engine.query_info("CustomerDetectionQuery")["param_values"] == {"distance_to_entrance": "1.0"}
    bad = CUSTOMER_QUERY.replace("printeps:Kinect ;", "printeps:Nothing ;")
    info = engine.register(bad.replace("CustomerDetectionQuery", "Q2"))
    assert "returned no value" in info["param_error"]
