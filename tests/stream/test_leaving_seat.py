"""Leaving-seat detection (ontology/queries/leaving_seat.rq) on simulated table sensors, posting
RDF directly to the engine. The table-empty time is the ontology's printeps:tableEmptyTime (20 s):
a departure is reported in the first window [c - 20 s, c) without a customer at the table, i.e.
the first c > last_seen + 20000, once (ISTREAM)."""

from __future__ import annotations

import os

from pyoxigraph import Literal, NamedNode
from table_scenarios import (
    LEAVING_SEAT_QUERY,
    TABLES,
    P,
    departures,
    mapper,
    messages,
    replay,
    teahouse_object,
)

from gateway.rdf.terms import RDF_TYPE, XSD_DECIMAL


def _register(engine) -> dict:
    return engine.register(LEAVING_SEAT_QUERY)


def test_the_query_reads_its_parameters_and_windows(engine):
    info = _register(engine)
    assert info["name"] == "LeavingSeatQuery" and info["operator"] == "ISTREAM"
    assert info["param_values"] == {"table_empty_time": '"20"^^<http://www.w3.org/2001/XMLSchema#decimal>'}
    assert [(w["name"].rsplit("/", 1)[-1], w["range_ms"], w["step_ms"]) for w in info["windows"]] == [
        ("before", 120_000, 1000), ("recent", 20_000, 1000)]
    # what a table sensor sends besides (positions, tables, staff …) is dropped on arrival
    assert info["relevant_predicates"] == sorted(P + p for p in ("location", "locationId", "objectType")) + [
        "http://www.w3.org/1999/02/22-rdf-syntax-ns#type"]


def test_the_proposed_mapping_of_a_teahouse_object():
    triples = set(mapper().map(teahouse_object("c7", "Customer", "table2", 0.4), 1500, "teahouse_object"))
    n = lambda local: NamedNode(P + local)  # noqa: E731
    assert triples == {
        (n("c7"), n("objectType"), Literal("Customer")),
        (n("c7"), n("location"), Literal("table2")),
        (n("c7"), n("positionAtTime"), n("c7_t1500")),
        (n("c7_t1500"), n("x"), Literal("1.25", datatype=XSD_DECIMAL)),
        (n("c7_t1500"), n("y"), Literal("2.5", datatype=XSD_DECIMAL)),
        (n("c7_t1500"), n("distance"), Literal("0.4", datatype=XSD_DECIMAL)),
    }


def test_a_party_leaves(engine):
    _register(engine)
    party = {"table2": [("c1", "Customer", 0, 30), ("c2", "Customer", 0, 25.5)]}
    events = replay(engine, messages(party, ["table1", "table2"], hz=2, seconds=80))
    # the last customer was seen at 29500; nobody in [c - 20000, c) first for c = 50000
    assert departures(events) == [(50_000, "table2", 29_500)]
    assert all(e["window"]["end"] % 1000 == 0 for e in events) and len(events) == 79  # every window reported


def test_a_short_absence_is_not_a_departure(engine):
    _register(engine)
    # c1 is out of sight from 10 s to 25 s (15 s < 20 s), then stays until 40 s
    presence = {"table2": [("c1", "Customer", 0, 10), ("c1", "Customer", 25, 40)]}
    events = replay(engine, messages(presence, ["table2"], hz=2, seconds=90))
    assert departures(events) == [(60_000, "table2", 39_500)]


def test_staff_and_empty_tables_are_not_departures(engine):
    _register(engine)
    presence = {"table1": [("s1", "Staff", 0, 5)], "table3": [("c3", "Customer", 0, 5)]}
    events = replay(engine, messages(presence, ["table1", "table2", "table3"], hz=2, seconds=40))
    assert departures(events) == [(25_000, "table3", 4_500)]


def test_two_tables_and_a_return(engine):
    _register(engine)
    presence = {
        "table1": [("a", "Customer", 0, 12)],
        "table4": [("b", "Customer", 0, 30), ("b", "Customer", 60, 70)],  # back after 30 s, leaves again
    }
    events = replay(engine, messages(presence, ["table1", "table4"], hz=5, seconds=100))
    assert departures(events) == [(32_000, "table1", 11_800), (50_000, "table4", 29_800),
                                  (90_000, "table4", 69_800)]


def test_heartbeats_drive_detection_when_sensors_fall_silent(engine):
    _register(engine)
    # only customers are published (no table heartbeats); then nothing at all
    events = replay(engine, [(ts, m) for ts, m in messages({"table2": [("c1", "Customer", 0, 3)]}, ["table2"],
                                                              hz=1, seconds=3) if m["type"] == "Customer"],
                    flush_ms=30_000)
    assert departures(events) == [(23_000, "table2", 2_000)]


def test_the_table_empty_time_comes_from_the_ontology(engine, ontology_copy):
    _register(engine)
    text = ontology_copy.read_text(encoding="utf-8")
    old = 'printeps:tableEmptyTime "20"^^xsd:decimal'
    assert old in text
    ontology_copy.write_text(text.replace(old, 'printeps:tableEmptyTime "5"^^xsd:decimal'), encoding="utf-8")
    st = ontology_copy.stat()
    os.utime(ontology_copy, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
    events = replay(engine, messages({"table2": [("c1", "Customer", 0, 10)]}, ["table2"], hz=2, seconds=30))
    assert departures(events) == [(15_000, "table2", 9_500)]  # 5 s after the last sighting, not 20
    info = engine.query_info("LeavingSeatQuery")
    assert info["windows"][1]["range_ms"] == 5000


def test_a_wrong_table_empty_time_is_reported_not_guessed(engine, ontology_copy):
    text = ontology_copy.read_text(encoding="utf-8")
    ontology_copy.write_text(text.replace('printeps:tableEmptyTime "20"^^xsd:decimal',
                                          'printeps:tableEmptyTime "0.1"^^xsd:decimal'), encoding="utf-8")
    info = _register(engine)
    assert "shorter than the window's STEP" in info["param_error"]
    events: list[dict] = []
    engine.subscribe(events.append)
    m = mapper()
    engine.push(TABLES, 0, m.map(teahouse_object("c1", "Customer", "table2"), 0, "teahouse_object"))
    engine.advance(2000)
    assert events and all(e["kind"] == "error" for e in events)


def test_the_ontology_tables_are_what_the_query_joins(engine):
    # a table that is not in the ontology is never reported (the join with the ontology fails)
    _register(engine)
    events = replay(engine, messages({"patio": [("c1", "Customer", 0, 2)]}, ["patio"], hz=2, seconds=40))
    assert departures(events) == []
    # (the ontology's tables carry their sensor id)
    triples = engine.ontology.triples
    assert (NamedNode(P + "table2"), NamedNode(P + "locationId"), Literal("table2")) in triples
    assert (NamedNode(P + "table2"), RDF_TYPE, NamedNode(P + "Table")) in triples
