"""Window semantics of the stream engine (RSP-QL): boundaries at the edges, every window evaluated
(empty ones too), bounded catch-up over gaps, late data, count windows, several windows per query,
static joins, stream operators, and the report policies."""

from __future__ import annotations

import pytest
from pyoxigraph import Literal, NamedNode

from gateway.rdf.terms import XSD_INTEGER
from gateway.stream import QueryParseError, StreamEngine, StreamError

S1, S2 = "http://ex/s1", "http://ex/s2"
EX = "http://ex/"
HEAD = "REGISTER QUERY {name} AS PREFIX ex: <http://ex/> PREFIX f: <http://larkc.eu/csparql/sparql/jena/ext#>\n"
COUNT_Q = HEAD + "SELECT (COUNT(*) AS ?n) (MIN(?v) AS ?lo) (MAX(?v) AS ?hi) FROM STREAM <" + S1 + "> {w} WHERE {{ ?s ex:v ?v }}"


def triple(i: int, value: int | None = None, p: str = "v"):
    return (NamedNode(f"{EX}r{i}"), NamedNode(EX + p), Literal(str(i if value is None else value), datatype=XSD_INTEGER))


def collect(engine, **kw):
    events: list[dict] = []
    engine.subscribe(events.append, **kw)
    return events


def rows(events):
    """(window end, first row) of every reported window."""
    return [(e["window"]["end"], e["rows"][0] if e["rows"] else None) for e in events if e["kind"] == "result"]


def counts(events):
    return [(e["window"]["end"], e["rows"][0]["n"]) for e in events if e["kind"] == "result"]


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


@pytest.mark.parametrize("fast", [True, False], ids=["fast-path", "general"])
def test_sliding_window_edges(settings, fast):
    # RANGE 3s STEP 1s: the window closing at c holds c-3000 <= ts < c
    engine = StreamEngine(settings.model_copy(update={"fast_path": fast}))
    engine.register(COUNT_Q.format(name="q", w="[RANGE 3s STEP 1s]"))
    events = collect(engine)
    for ts in (0, 999, 1000, 3999):
        engine.push(S1, ts, [triple(ts)])
    engine.advance(4000)  # closes 4000 (and nothing else: 0 started the clock, 1000..3000 closed before)
    engine.advance(4001)
    engine.advance(5000)
    got = dict(rows(events))
    assert got[1000] == {"n": 2, "lo": 0, "hi": 999}        # 0 and 999; 1000 is the next window's
    assert got[4000] == {"n": 2, "lo": 1000, "hi": 3999}    # 1000 = c - r is in, 999 is out
    assert got[5000] == {"n": 1, "lo": 3999, "hi": 3999}
    assert {e["path"] for e in events} == {"fast" if fast else "oxigraph"}


def test_tumbling_window_edges(engine):
    engine.register(COUNT_Q.format(name="q", w="[RANGE 2s TUMBLING]"))
    events = collect(engine)
    for ts in (0, 1999, 2000, 3999, 4000):
        engine.push(S1, ts, [triple(ts)])
    assert rows(events) == [(2000, {"n": 2, "lo": 0, "hi": 1999}), (4000, {"n": 2, "lo": 2000, "hi": 3999})]


def test_iso_durations(engine):
    info = engine.register(COUNT_Q.format(name="q", w="[RANGE PT1.5S STEP PT0.5S]"))
    assert (info["windows"][0]["range_ms"], info["windows"][0]["step_ms"]) == (1500, 500)


@pytest.mark.parametrize("fast", [True, False], ids=["fast-path", "general"])
def test_every_window_is_reported_and_an_empty_count_is_zero(settings, fast):
    engine = StreamEngine(settings.model_copy(update={"fast_path": fast}))
    engine.register(COUNT_Q.format(name="q", w="[RANGE 1s STEP 1s]"))
    grouped = HEAD.format(name="g") + f"SELECT ?s (COUNT(*) AS ?n) FROM STREAM <{S1}> [RANGE 1s STEP 1s] WHERE {{ ?s ex:v ?v }} GROUP BY ?s"
    engine.register(grouped)
    events = collect(engine)
    engine.push(S1, 500, [triple(1)])
    engine.push(S1, 3500, [triple(2)])
    engine.advance(4000)
    q = [e for e in events if e["query"] == "q"]
    assert counts(q) == [(1000, 1), (2000, 0), (3000, 0), (4000, 1)]
    empty = q[1]
    assert empty["window"] == {"start": 1000, "end": 2000, "triples": 0}
    assert empty["rows"] == [{"n": 0}]  # COUNT over nothing is 0; MIN/MAX are unbound
    assert [(e["window"]["end"], len(e["rows"])) for e in events if e["query"] == "g"] == [
        (1000, 1), (2000, 0), (3000, 0), (4000, 1)]  # GROUP BY over nothing: no group at all
    stats = engine.query_info("q")["stats"]
    assert stats["windows"] == 4 and stats["empty_windows"] == 2


def test_a_long_gap_reports_its_first_and_last_windows(settings):
    engine = StreamEngine(settings.model_copy(update={"max_catchup_windows": 5}))
    engine.register(COUNT_Q.format(name="q", w="[RANGE 1s STEP 1s]"))
    events = collect(engine)
    engine.push(S1, 500, [triple(1)])
    engine.push(S1, 3_600_500, [triple(2)])  # an hour later
    engine.advance(3_601_000)
    got = [(e["window"]["end"], e["rows"][0]["n"], e.get("skipped", 0)) for e in events]
    # the empty stretch 2000 … 3_600_000 (3599 windows): the first 4 and the last (saying how many were left out)
    assert got == [(1000, 1, 0), (2000, 0, 0), (3000, 0, 0), (4000, 0, 0), (5000, 0, 0),
                   (3_600_000, 0, 3594), (3_601_000, 1, 0)]
    assert [e["seq"] for e in events] == list(range(1, 8))
    stats = engine.query_info("q")["stats"]
    assert stats["skipped_windows"] == 3594 and stats["reported"] == 7


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


def test_literals_are_canonical_so_f_timestamp_finds_them(settings):
    # "03"^^xsd:integer and "3.10"^^xsd:decimal are stored as "3" and "3.1" (XSD 1.1 canonical forms)
    for fast in (True, False):
        engine = StreamEngine(settings.model_copy(update={"fast_path": fast}))
        engine.register(HEAD.format(name="q") + f"SELECT ?o (f:timestamp(?s, ex:v, ?o) AS ?t) FROM STREAM <{S1}> "
                        "[RANGE 1s STEP 1s] WHERE { ?s ex:v ?o }")
        events = collect(engine)
        xsd = "http://www.w3.org/2001/XMLSchema#"
        engine.push(S1, 10, [(NamedNode(EX + "a"), NamedNode(EX + "v"), Literal("03", datatype=NamedNode(xsd + "int"))),
                             (NamedNode(EX + "b"), NamedNode(EX + "v"), Literal("3.10", datatype=NamedNode(xsd + "decimal")))])
        engine.advance(1000)
        (event,) = events
        assert sorted((str(r["o"]), r["t"]) for r in event["rows"]) == [("3", 10), ("3.1", 10)]
        assert sorted(str(r["o"]) for r in event.terms) == [
            '"3"^^<http://www.w3.org/2001/XMLSchema#integer>', '"3.1"^^<http://www.w3.org/2001/XMLSchema#decimal>']


def test_late_messages_are_dropped_counted_and_never_seen(engine):
    engine.register(COUNT_Q.format(name="q", w="[RANGE 2s STEP 1s]"))
    events = collect(engine)
    engine.push(S1, 1500, [triple(1)])
    engine.push(S1, 2500, [triple(2)])  # closes the window ending 2000
    engine.push(S1, 2100, [triple(3)])  # out of order but its windows are open: accepted
    report = engine.push(S1, 1900, [triple(4)])  # older than the closed window: late
    assert report["late_for"] == ["q"]
    engine.advance(4000)
    # 1900 would fall in the window ending 3000 ([1000, 3000)) too: a late triple is seen by no window
    assert rows(events) == [(2000, {"n": 1, "lo": 1, "hi": 1}), (3000, {"n": 3, "lo": 1, "hi": 3}),
                            (4000, {"n": 2, "lo": 2, "hi": 3})]
    assert engine.query_info("q")["stats"]["late_dropped"] == 1
    assert engine.advance(1000) == 0  # a heartbeat from the past changes nothing


def test_count_window_keeps_the_last_triples(engine):
    engine.register(COUNT_Q.format(name="q", w="[RANGE TRIPLES 3]"))
    events = collect(engine)
    for i in range(5):
        engine.push(S1, 10 * i, [triple(i)])
    assert [r for _, r in rows(events)] == [
        {"n": 1, "lo": 0, "hi": 0}, {"n": 2, "lo": 0, "hi": 1}, {"n": 3, "lo": 0, "hi": 2},
        {"n": 3, "lo": 1, "hi": 3}, {"n": 3, "lo": 2, "hi": 4},
    ]


def test_count_window_edges(engine):
    engine.register(COUNT_Q.format(name="q", w="[RANGE TRIPLES 3]"))
    events = collect(engine)
    engine.push(S1, 10, [triple(1), triple(2)])
    engine.push(S1, 10, [triple(3), triple(4)])  # the same instant: still in order of arrival
    assert rows(events)[-1] == (11, {"n": 3, "lo": 2, "hi": 4})  # the last 3 of 4 triples
    assert engine.push(S1, 5, [triple(5)])["late_for"] == ["q"]  # each message closed a window


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
    info = engine.register(q.format(name="q2"))
    assert info["fast_path"] is True
    events = collect(engine)
    engine.push(S2, 100, [triple(1)])
    engine.push(S1, 3500, [triple(5)])  # closes 1000, 2000, 3000: S2's reading is within its 5 s range
    assert rows(events)[-1] == (3000, {"s": EX + "r1", "l": "one", "n": 1})


def test_a_join_with_the_ontology(settings):
    # the static ontology joined on the fast path and on the general path: the same rows
    q = ("REGISTER QUERY q AS PREFIX printeps: <http://printeps.org/cafe/entrance/>\n"
         "SELECT ?table (COUNT(*) AS ?seen) FROM STREAM <http://ex/tables> [RANGE 2s STEP 1s]\n"
         "FROM <http://printeps.org/cafe/ontology>\n"
         "WHERE { ?table a printeps:Table ; printeps:locationId ?id . ?p printeps:location ?id } GROUP BY ?table")
    outs = []
    for fast in (True, False):
        engine = StreamEngine(settings.model_copy(update={"fast_path": fast}))
        assert engine.register(q)["fast_path"] is fast
        events = collect(engine)
        loc = NamedNode("http://printeps.org/cafe/entrance/location")
        engine.push("http://ex/tables", 100, [(NamedNode(EX + "p1"), loc, Literal("table2")),
                                              (NamedNode(EX + "p2"), loc, Literal("table2")),
                                              (NamedNode(EX + "p3"), loc, Literal("nowhere"))])
        engine.advance(1000)
        outs.append([(e["window"]["end"], [(str(r["table"]), str(r["seen"])) for r in e.terms]) for e in events])
    assert outs[0] == outs[1] == [(1000, [("<http://printeps.org/cafe/entrance/table2>",
                                          '"2"^^<http://www.w3.org/2001/XMLSchema#integer>')])]


def test_named_windows_and_filter_not_exists(engine):
    # seen in the last 5 s but not in the last 2 s (two windows over one stream)
    q = ("REGISTER QUERY gone AS PREFIX ex: <http://ex/> PREFIX w: <http://ex/w/>\n"
         f"SELECT ?s FROM NAMED WINDOW w:long ON <{S1}> [RANGE 5s STEP 1s]\n"
         f"FROM NAMED WINDOW w:short ON STREAM <{S1}> [RANGE 2s STEP 1s]\n"
         "WHERE { WINDOW w:long { ?s ex:v ?v } FILTER NOT EXISTS { WINDOW w:short { ?s ex:v ?x } } }")
    info = engine.register(q)
    assert [w["name"] for w in info["windows"]] == ["http://ex/w/long", "http://ex/w/short"]
    assert info["fast_path"] is False and "named windows" in info["not_compilable"]
    events = collect(engine)
    engine.push(S1, 500, [triple(1)])
    engine.push(S1, 1500, [triple(2)])
    engine.advance(6000)
    gone = {e["window"]["end"]: sorted(r["s"][-2:] for r in e["rows"]) for e in events}
    assert gone == {1000: [], 2000: [], 3000: ["r1"], 4000: ["r1", "r2"], 5000: ["r1", "r2"], 6000: ["r2"]}


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
    engine.register(HEAD.format(name="a") + "ASK FROM STREAM <" + S1 + "> [RANGE 1s STEP 1s] WHERE { ?s ex:v 2 }")
    events = collect(engine)
    engine.push(S1, 100, [triple(1), triple(2)])
    engine.advance(1000)
    by_query = {e["query"]: e["rows"] for e in events if e["kind"] == "result"}
    assert by_query["c"] == [{"subject": EX + "r2", "predicate": EX + "seen", "object": True}]
    assert by_query["a"] == [{"ask": True}]
    with pytest.raises(QueryParseError, match="REGISTER STREAM needs CONSTRUCT"):
        engine.register(HEAD.format(name="s").replace("REGISTER QUERY", "REGISTER STREAM") + "ASK FROM STREAM <"
                        + S1 + "> [RANGE 1s STEP 1s] WHERE { ?s ex:v 2 }")


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
    (event,) = [e for e in events if e["kind"] == "result" and e["rows"]]
    assert event["path"] == "oxigraph" and event["rows"][0]["cnt"] == 3
    assert engine.query_info("CustomerDetectionQuery")["stats"]["fallbacks"] >= 1


def test_after_a_fallback_the_next_windows_skip_the_doomed_fast_try(engine):
    """Doubles in arithmetic fall back in every window (the ROS Entrance readings): after one
    fallback the next 1, 2, 4, … windows go to the general path without trying the fast path
    (a failed try costs more than the general path); exact numbers are on the fast path again
    after the run of skipped windows, and every window answers as the general path does."""
    from csparql_scenarios import CUSTOMER_QUERY

    engine.register(CUSTOMER_QUERY)
    P = "http://printeps.org/cafe/entrance/"
    xsd = "http://www.w3.org/2001/XMLSchema#"
    events = collect(engine)

    def reading(k: int, ts: int, distance: str, datatype: str) -> None:
        customer, node = NamedNode(f"{P}c{k // 5}"), NamedNode(f"{P}r{k}")
        engine.push("http://printeps.org/cafe/entrance", ts, [
            (customer, NamedNode("http://www.w3.org/1999/02/22-rdf-syntax-ns#type"), NamedNode(P + "Customer")),
            (customer, NamedNode(P + "positionAtTime"), node),
            (node, NamedNode(P + "distance"), Literal(distance, datatype=NamedNode(xsd + datatype)))])

    for k in range(20):  # one reading a second, closing one non-empty window each
        reading(k, 500 + 1000 * k, f"{3.9 - 0.3 * (k % 5):.1f}", "double")
    stats = engine.query_info("CustomerDetectionQuery")["stats"]
    # the first window holds one reading (no difference to compute): fast; the 18 others fall back,
    # and only 4 of them try the fast path first (windows 2, 4, 7 and 12: then 1, 2, 4, 8 skipped)
    assert stats["windows"] == 19 and stats["fast"] == 1 and stats["general"] == stats["fallbacks"] == 18
    assert stats["fast_skipped"] == 14
    for k in range(20, 60):
        reading(k, 500 + 1000 * k, f"{3.9 - 0.3 * (k % 5):.1f}", "decimal")
    stats = engine.query_info("CustomerDetectionQuery")["stats"]
    assert stats["fast"] >= 20 and stats["general"] == stats["fallbacks"]
    detected = [e for e in events if e["kind"] == "result" and e["rows"]]
    assert {e["path"] for e in detected} == {"fast", "oxigraph"}
    assert len({(e["rows"][0]["cnt"], e["path"]) for e in detected}) >= 2  # the same detections on either path


def test_triples_the_query_cannot_match_are_not_kept(engine):
    info = engine.register(COUNT_Q.format(name="q", w="[RANGE 1h STEP 1h]"))
    assert info["relevant_predicates"] == [EX + "v"]
    engine.register(HEAD.format(name="all") + f"SELECT (COUNT(*) AS ?n) FROM STREAM <{S1}> [RANGE 1h STEP 1h] "
                    "WHERE { ?s ?p ?o }")
    engine.push(S1, 1, [triple(1), triple(2, p="other"), triple(3, p="other")])
    assert engine.query_info("q")["buffered_triples"] == {S1: 1}
    assert engine.query_info("all")["buffered_triples"] == {S1: 3}


# -- stream operators ---------------------------------------------------------------------------


def test_istream_and_dstream(engine):
    base = f"SELECT {{op}} ?s FROM STREAM <{S1}> [RANGE 2s STEP 1s] WHERE {{{{ ?s ex:v ?v }}}}"
    for op in ("ISTREAM", "DSTREAM", "RSTREAM"):
        engine.register(HEAD.format(name=op.lower()) + base.format(op=op))
    events = collect(engine)
    engine.push(S1, 100, [triple(1)])
    engine.push(S1, 1100, [triple(2)])
    engine.advance(4000)
    seen = {op: [(e["window"]["end"], sorted(r["s"][-2:] for r in e["rows"])) for e in events if e["query"] == op]
            for op in ("istream", "dstream", "rstream")}
    assert seen["rstream"] == [(1000, ["r1"]), (2000, ["r1", "r2"]), (3000, ["r2"]), (4000, [])]
    assert seen["istream"] == [(1000, ["r1"]), (2000, ["r2"]), (3000, []), (4000, [])]
    assert seen["dstream"] == [(1000, []), (2000, []), (3000, ["r1"]), (4000, ["r2"])]
    assert events[0]["operator"] == "ISTREAM"


# -- results and subscribers --------------------------------------------------------------------


def test_results_keep_every_window_and_filter_nonempty(settings):
    engine = StreamEngine(settings.model_copy(update={"results_kept": 3}))
    engine.register(HEAD.format(name="q") + f"SELECT ?s FROM STREAM <{S1}> [RANGE 1s STEP 1s] WHERE {{ ?s ex:v ?v }}")
    events = collect(engine, nonempty=True)
    engine.push(S1, 100, [triple(1)])
    engine.push(S1, 1100, [triple(2)])
    engine.advance(6000)
    assert [r["window"]["end"] for r in engine.results("q")] == [4000, 5000, 6000]  # the last 3, empty ones too
    assert [r["window"]["end"] for r in engine.results("q", limit=2)] == [5000, 6000]
    assert [r["window"]["end"] for r in engine.results("q", nonempty=True)] == [1000, 2000]
    assert [e["window"]["end"] for e in events] == [1000, 2000]  # subscribed with nonempty=True


# -- report policies ----------------------------------------------------------------------------


def test_report_non_empty_is_c_sparql_behaviour(engine):
    engine.register(COUNT_Q.format(name="q", w="[RANGE 1s STEP 1s]").replace(" AS ", " REPORT NON EMPTY AS ", 1))
    events = collect(engine)
    engine.push(S1, 500, [triple(1)])
    engine.push(S1, 3500, [triple(2)])
    engine.advance(4000)
    assert counts(events) == [(1000, 1), (4000, 1)]
    assert engine.query_info("q")["report"] == {"trigger": "window_close", "non_empty": True, "period_ms": None}
    assert engine.query_info("q")["stats"]["empty_windows"] == 2


def test_report_on_content_change(engine):
    engine.register(COUNT_Q.format(name="q", w="[RANGE 1s STEP 1s]"), report="content change")
    events = collect(engine)
    engine.push(S1, 100, [triple(1)])     # window [0, 1000) now holds 1 triple
    engine.push(S1, 200, [triple(2)])     # 2 triples
    engine.advance(300)                   # a heartbeat, nothing changed: no report
    engine.push(S1, 1500, [triple(3)])    # the window [1000, 2000): triple 3 (1 and 2 left)
    engine.advance(2600)                  # [2000, 3000) is empty: triple 3 left
    engine.advance(2700)                  # still empty: no report
    got = [(e["window"]["end"], e["window"].get("at"), e["rows"][0]["n"]) for e in events]
    assert got == [(1000, 101, 1), (1000, 201, 2), (2000, 1501, 1), (3000, 2600, 0)]


def test_report_periodic_shows_a_window_filling_up(engine):
    engine.register(COUNT_Q.format(name="q", w="[RANGE 2s TUMBLING]").replace(" AS ", " REPORT PERIODIC 500ms AS ", 1))
    events = collect(engine)
    for ts in (100, 600, 1100, 1600, 2100):
        engine.push(S1, ts, [triple(ts)])
    engine.advance(2500)
    got = [(e["window"]["end"], e["window"].get("at"), e["rows"][0]["n"]) for e in events]
    # the window [0, 2000) at 500, 1000, 1500 (partial) and 2000 (closed); then [2000, 4000) at 2500
    assert got == [(2000, 500, 1), (2000, 1000, 2), (2000, 1500, 3), (2000, None, 4), (4000, 2500, 1)]


def test_computed_every_is_periodic(engine):
    info = engine.register(COUNT_Q.format(name="q", w="[RANGE 2s STEP 1s]").replace(" AS ", " COMPUTED EVERY 2s AS ", 1))
    assert info["report"] == {"trigger": "periodic", "non_empty": False, "period_ms": 2000}
    events = collect(engine)
    for ts in range(100, 6000, 500):
        engine.push(S1, ts, [triple(ts)])
    assert [e["window"]["end"] for e in events] == [2000, 4000]


def test_policy_given_at_registration_overrides_the_query(engine):
    text = COUNT_Q.format(name="q", w="[RANGE 1s STEP 1s]").replace(" AS ", " REPORT NON EMPTY AS ", 1)
    info = engine.register(text, report="periodic 500ms and non empty")
    assert info["report"] == {"trigger": "periodic", "non_empty": True, "period_ms": 500}
    with pytest.raises(QueryParseError, match="unknown report policy"):
        engine.register(text, report="sometimes", replace=True)
