"""REGISTER STREAM s AS CONSTRUCT …: the results form a timestamped RDF stream other queries read."""

from __future__ import annotations

import pytest
from pyoxigraph import Literal, NamedNode

from gateway.rdf.terms import XSD_INTEGER
from gateway.stream import QueryParseError

EX = "http://ex/"
RAW = "http://ex/raw"
PREFIX = "PREFIX ex: <http://ex/>\n"
HOT = ("REGISTER STREAM ex:hot AS " + PREFIX + "CONSTRUCT { ?s ex:hot ?v } FROM STREAM <" + RAW
       + "> [RANGE 1s STEP 1s] WHERE { ?s ex:temp ?v FILTER(?v > 30) }")
COUNT_HOT = ("REGISTER QUERY alarms AS " + PREFIX + "SELECT (COUNT(DISTINCT ?s) AS ?n) FROM STREAM ex:hot "
             "[RANGE 2s STEP 1s] WHERE { ?s ex:hot ?v }")


def reading(name: str, value: int):
    return (NamedNode(EX + name), NamedNode(EX + "temp"), Literal(str(value), datatype=XSD_INTEGER))


def results(events, query):
    return [(e["window"]["end"], e["rows"]) for e in events if e["kind"] == "result" and e["query"] == query]


@pytest.mark.parametrize("downstream_first", [False, True])
def test_a_query_reads_another_querys_stream(engine, downstream_first):
    order = [COUNT_HOT, HOT] if downstream_first else [HOT, COUNT_HOT]
    for text in order:
        engine.register(text)
    assert engine.query_info("ex:hot")["output_stream"] == EX + "hot"
    events: list[dict] = []
    engine.subscribe(events.append)
    engine.push(RAW, 100, [reading("a", 35), reading("b", 20)])
    engine.push(RAW, 1100, [reading("b", 31)])
    engine.push(RAW, 2100, [reading("c", 10)])
    engine.advance(5000)
    # hot closes at 1000 (a), 2000 (b), 3000 (nothing), … and stamps its output with that instant;
    # alarms' window closing at c holds what hot emitted in [c - 2000, c)
    assert results(events, "ex:hot")[:3] == [
        (1000, [{"subject": EX + "a", "predicate": EX + "hot", "object": 35}]),
        (2000, [{"subject": EX + "b", "predicate": EX + "hot", "object": 31}]),
        (3000, []),
    ]
    assert results(events, "alarms") == [(2000, [{"n": 1}]), (3000, [{"n": 2}]), (4000, [{"n": 1}]),
                                         (5000, [{"n": 0}])]
    assert engine.stream_stats[EX + "hot"] == {"messages": 2, "triples": 2}
    assert engine.query_info("ex:hot")["stats"]["derived_triples"] == 2


def test_an_empty_output_still_moves_the_readers_clock(engine):
    engine.register(HOT)
    engine.register(COUNT_HOT)
    events: list[dict] = []
    engine.subscribe(events.append, query="alarms")
    engine.push(RAW, 100, [reading("a", 1)])  # never hot
    engine.advance(4000)
    assert results(events, "alarms") == [(2000, [{"n": 0}]), (3000, [{"n": 0}]), (4000, [{"n": 0}])]


def test_three_queries_in_a_chain_and_istream(engine):
    engine.register(HOT.replace("CONSTRUCT {", "CONSTRUCT ISTREAM {").replace("[RANGE 1s STEP 1s]", "[RANGE 3s STEP 1s]"))
    engine.register("REGISTER STREAM ex:alert AS " + PREFIX + "CONSTRUCT { ?s a ex:Alert } FROM STREAM ex:hot "
                    "[RANGE 1s STEP 1s] WHERE { ?s ex:hot ?v }")
    engine.register("REGISTER QUERY alerts AS " + PREFIX + "SELECT ?s FROM STREAM ex:alert [RANGE 1s STEP 1s] "
                    "WHERE { ?s a ex:Alert }")
    events: list[dict] = []
    engine.subscribe(events.append)
    engine.push(RAW, 100, [reading("a", 35)])
    engine.advance(6000)
    # ISTREAM: a is new at 1000 only (it stays in hot's 3 s window until 4000 but is not repeated)
    assert [end for end, rows in results(events, "ex:hot") if rows] == [1000]
    assert [end for end, rows in results(events, "ex:alert") if rows] == [2000]
    assert [(end, rows) for end, rows in results(events, "alerts") if rows] == [(3000, [{"s": EX + "a"}])]


def test_cycles_are_refused_where_they_close(engine):
    engine.register("REGISTER STREAM ex:a AS " + PREFIX + "CONSTRUCT { ?s ?p ?o } FROM STREAM ex:b "
                    "[RANGE 1s STEP 1s] WHERE { ?s ?p ?o }")
    text = ("REGISTER STREAM ex:b AS " + PREFIX + "CONSTRUCT { ?s ?p ?o }\nFROM STREAM <" + RAW + "> [RANGE 1s STEP 1s]\n"
            "FROM STREAM ex:a [RANGE 1s STEP 1s] WHERE { ?s ?p ?o }")
    with pytest.raises(QueryParseError) as info:
        engine.register(text)
    err = info.value
    assert "stream cycle: <http://ex/b> → <http://ex/a> → <http://ex/b>" in err.message
    assert (err.line, err.column) == (4, 13)  # at "ex:a" in FROM STREAM ex:a
    with pytest.raises(QueryParseError, match="would read its own output") as own:
        engine.register("REGISTER STREAM s AS CONSTRUCT { ?s ?p ?o }\nFROM STREAM <s> [RANGE 1s STEP 1s] WHERE { ?s ?p ?o }")
    assert (own.value.line, own.value.column) == (2, 13)
    # nothing was registered by the refused queries
    assert [q["name"] for q in engine.queries()] == ["ex:a"]


def test_replacing_a_query_is_checked_like_a_new_one(engine):
    engine.register(HOT)
    engine.register("REGISTER STREAM ex:cool AS " + PREFIX + "CONSTRUCT { ?s ex:cool 1 } FROM STREAM ex:hot "
                    "[RANGE 1s STEP 1s] WHERE { ?s ex:hot ?v }")
    with pytest.raises(QueryParseError, match="stream cycle"):
        engine.register(HOT.replace("FROM STREAM <" + RAW + ">", "FROM STREAM ex:cool"), replace=True)
    engine.unregister("ex:cool")
    engine.register(HOT.replace("FROM STREAM <" + RAW + ">", "FROM STREAM ex:cool"), replace=True)  # no cycle now
