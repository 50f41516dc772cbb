"""Window semantics of the stream engine: event time, lateness, bounds, count windows, graphs."""

from __future__ import annotations

import pytest
from pyoxigraph import Literal, NamedNode

from gateway.rdf.terms import XSD_INTEGER
from gateway.stream import QueryParseError, StreamEngine, StreamError

S1, S2 = "http://ex/s1", "http://ex/s2"
EX = "http://ex/"
HEAD = "REGISTER QUERY {name} AS PREFIX ex: <http://ex/> PREFIX f: <http://larkc.eu/csparql/sparql/jena/ext#>\n"
COUNT_Q = HEAD + "SELECT (COUNT(*) AS ?n) (MIN(?v) AS ?lo) (MAX(?v) AS ?hi) FROM STREAM <" + S1 + "> {w} WHERE {{ ?s ex:v ?v }}"


def triple(i: int, value: int | None = None):
    return (NamedNode(f"{EX}r{i}"), NamedNode(EX + "v"), Literal(str(i if value is None else value), datatype=XSD_INTEGER))


def collect(engine):
    events: list[dict] = []
    engine.subscribe(events.append)
    return events


def rows(events):
    return [(e["window"]["end"], e["rows"][0]) for e in events if e["kind"] == "result"]


def test_windows_are_epoch_aligned_and_half_open(engine):
    engine.register(COUNT_Q.format(name="q", w="[RANGE 3s STEP 1s]"))
    events = collect(engine)
    for ts in (1000, 1999, 2000, 3500, 4000, 7000):
        engine.push(S1, ts, [triple(ts)])
    # closes at 2000 (1000,1999), 3000, 4000 (1000..3500), 5000 (2000..4000), 6000, 7000 (4000)
    assert rows(events) == [
        (2000, {"n": 2, "lo": 1000, "hi": 1999}),
        (3000, {"n": 3, "lo": 1000, "hi": 2000}),
        (4000, {"n": 4, "lo": 1000, "hi": 3500}),
        (5000, {"n": 3, "lo": 2000, "hi": 4000}),
        (6000, {"n": 2, "lo": 3500, "hi": 4000}),
        (7000, {"n": 1, "lo": 4000, "hi": 4000}),
    ]


def test_f_timestamp_is_the_latest_occurrence(engine):
    q = HEAD + ("SELECT ?s (f:timestamp(?s, ex:v, ?v) AS ?t) FROM STREAM <" + S1 + "> [RANGE 10s STEP 1s] "
                "WHERE {{ ?s ex:v ?v }}")
    engine.register(q.format(name="ts"))
    events = collect(engine)
    engine.push(S1, 100, [triple(1)])
    engine.push(S1, 600, [triple(1)])  # the same triple again
    engine.advance(1000)
    (event,) = [e for e in events if e["kind"] == "result"]
    assert event["rows"] == [{"s": EX + "r1", "t": 600}]


def test_late_messages_are_dropped_and_counted(engine):
    engine.register(COUNT_Q.format(name="q", w="[RANGE 2s STEP 1s]"))
    events = collect(engine)
    engine.push(S1, 1500, [triple(1)])
    engine.push(S1, 2500, [triple(2)])  # closes the window ending 2000
    engine.push(S1, 2100, [triple(3)])  # out of order but its window (ending 3000) is open: accepted
    report = engine.push(S1, 1900, [triple(4)])  # older than the closed window: late
    assert report["late_for"] == ["q"]
    engine.advance(3000)
    assert rows(events)[-1] == (3000, {"n": 3, "lo": 1, "hi": 3})
    assert engine.query_info("q")["stats"]["late_dropped"] == 1


def test_empty_stretches_are_skipped_not_evaluated(engine):
    engine.register(COUNT_Q.format(name="q", w="[RANGE 1s STEP 1s]"))
    events = collect(engine)
    engine.push(S1, 500, [triple(1)])
    engine.push(S1, 3_600_500, [triple(2)])  # an hour later
    engine.advance(3_601_000)
    assert [end for end, _ in rows(events)] == [1000, 3_601_000]
    stats = engine.query_info("q")["stats"]
    assert stats["windows"] == 2 and stats["skipped_windows"] == 3599


def test_count_window_keeps_the_last_triples(engine):
    engine.register(COUNT_Q.format(name="q", w="[RANGE TRIPLES 3]"))
    events = collect(engine)
    for i in range(5):
        engine.push(S1, 10 * i, [triple(i)])
    assert [r for _, r in rows(events)] == [
        {"n": 1, "lo": 0, "hi": 0}, {"n": 2, "lo": 0, "hi": 1}, {"n": 3, "lo": 0, "hi": 2},
        {"n": 3, "lo": 1, "hi": 3}, {"n": 3, "lo": 2, "hi": 4},
    ]


def test_flood_is_bounded_and_counted(settings):
    engine = StreamEngine(settings.model_copy(update={"max_window_triples": 100}))
    engine.register(COUNT_Q.format(name="q", w="[RANGE 1h STEP 1h]"))
    for i in range(1000):
        engine.push(S1, i, [triple(i)])
    info = engine.query_info("q")
    assert info["buffered_triples"][S1] == 100
    assert info["stats"]["overflow_dropped"] == 900
    with pytest.raises(StreamError):
        engine.push(S1, 2000, [triple(0)] * (settings.max_message_triples + 1))


def test_two_streams_and_a_static_graph(engine):
    engine.add_static_graph("http://ex/static", {(NamedNode(EX + "r1"), NamedNode(EX + "label"), Literal("one"))})
    q = HEAD + ("SELECT ?s ?l (COUNT(*) AS ?n) FROM STREAM <" + S1 + "> [RANGE 2s STEP 1s] FROM STREAM <" + S2
                + "> [RANGE 5s STEP 1s] FROM <http://ex/static> WHERE {{ ?s ex:v ?v . ?s ex:label ?l }} GROUP BY ?s ?l")
    engine.register(q.format(name="q2"))
    events = collect(engine)
    engine.push(S2, 100, [triple(1)])
    engine.push(S1, 3500, [triple(5)])  # closes 1000, 2000, 3000: S2's reading is within its 5 s range
    assert rows(events)[-1] == (3000, {"s": EX + "r1", "l": "one", "n": 1})


def test_register_errors(engine):
    with pytest.raises(QueryParseError) as info:
        engine.register(COUNT_Q.format(name="q", w="[RANGE 1s STEP 1s]").replace("?v }", "?v . FILTER(?v > ) }"))
    assert info.value.line == 2 and info.value.column > 0
    with pytest.raises(QueryParseError, match="unknown static graph"):
        engine.register(HEAD.format(name="g") + f"SELECT * FROM STREAM <{S1}> [RANGE 1s STEP 1s] FROM <http://nope> WHERE {{}}")
    engine.register(COUNT_Q.format(name="q", w="[RANGE 1s STEP 1s]"))
    with pytest.raises(StreamError, match="already registered"):
        engine.register(COUNT_Q.format(name="q", w="[RANGE 1s STEP 1s]"))
    engine.register(COUNT_Q.format(name="q", w="[RANGE 2s STEP 1s]"), replace=True)
    assert engine.query_info("q")["windows"][0]["range_ms"] == 2000


def test_many_queries_are_bounded(settings):
    engine = StreamEngine(settings.model_copy(update={"max_queries": 2}))
    engine.register(COUNT_Q.format(name="a", w="[RANGE 1s STEP 1s]"))
    engine.register(COUNT_Q.format(name="b", w="[RANGE 1s STEP 1s]"))
    with pytest.raises(StreamError, match="at most 2"):
        engine.register(COUNT_Q.format(name="c", w="[RANGE 1s STEP 1s]"))


def test_a_failing_subscriber_does_not_stop_the_stream(engine):
    engine.register(COUNT_Q.format(name="q", w="[RANGE 1s STEP 1s]"))
    engine.subscribe(lambda event: 1 / 0)
    events = collect(engine)
    engine.push(S1, 100, [triple(1)])
    engine.push(S1, 1100, [triple(2)])
    assert rows(events) and engine.subscriber_errors == 1


def test_construct_and_ask_queries(engine):
    engine.register(HEAD.format(name="c") + "CONSTRUCT { ?s ex:seen true } FROM STREAM <" + S1
                    + "> [RANGE 1s STEP 1s] WHERE { ?s ex:v ?v FILTER(?v > 1) }")
    engine.register(HEAD.format(name="a").replace("REGISTER QUERY", "REGISTER STREAM") + "ASK FROM STREAM <" + S1
                    + "> [RANGE 1s STEP 1s] WHERE { ?s ex:v 2 }")
    events = collect(engine)
    engine.push(S1, 100, [triple(1), triple(2)])
    engine.advance(1000)
    by_query = {e["query"]: e["rows"] for e in events if e["kind"] == "result"}
    assert by_query["c"] == [{"subject": EX + "r2", "predicate": EX + "seen", "object": True}]
    assert by_query["a"] == [{"ask": True}]


def test_inexact_numbers_fall_back_to_the_general_path(engine):
    from csparql_scenarios import CUSTOMER_QUERY

    engine.register(CUSTOMER_QUERY)
    P = "http://printeps.org/cafe/entrance/"
    double = NamedNode("http://www.w3.org/2001/XMLSchema#double")
    events = collect(engine)
    for i, (ts, d) in enumerate([(500, "3.9"), (1500, "3.6"), (2500, "3.3"), (3500, "3.0"), (4500, "2.7")]):
        node = NamedNode(f"{P}r{i}")
        engine.push("http://printeps.org/cafe/entrance", ts, [
            (NamedNode(P + "c1"), NamedNode("http://www.w3.org/1999/02/22-rdf-syntax-ns#type"), NamedNode(P + "Customer")),
            (NamedNode(P + "c1"), NamedNode(P + "positionAtTime"), node),
            (node, NamedNode(P + "distance"), Literal(d, datatype=double)),
        ])
    (event,) = [e for e in events if e["kind"] == "result"]
    assert event["path"] == "oxigraph" and event["rows"][0]["cnt"] == 3
    assert engine.query_info("CustomerDetectionQuery")["stats"]["fallbacks"] >= 1
