"""The fast path's term table stays bounded by what its windows hold, not by the stream's history.

Why: the table gives every term it encodes an id, and a stream names new terms with every reading
(here, as in the teahouse's Entrance mapping, one node per customer's position at that time). The
table used to keep them all (up to two million terms): the soak's leak of pyoxigraph nodes
(docs/benchmarks.md, "Soak"). The answers must not change when the table is emptied between
windows, so the fast engine is checked against the general path window by window."""

from __future__ import annotations

from pyoxigraph import Literal, NamedNode

from gateway.config import StreamSettings
from gateway.stream import StreamEngine
from gateway.stream.fastpath import executor

P = "http://printeps.org/cafe/entrance/"
STREAM = "http://printeps.org/cafe/entrance"
RDF_TYPE = NamedNode("http://www.w3.org/1999/02/22-rdf-syntax-ns#type")
DECIMAL = NamedNode("http://www.w3.org/2001/XMLSchema#decimal")
QUERY = f"""REGISTER QUERY Approaching AS
PREFIX f: <http://larkc.eu/csparql/sparql/jena/ext#>
PREFIX rdf: <http://www.w3.org/1999/02/22-rdf-syntax-ns#>
PREFIX printeps: <{P}>
SELECT ?s (COUNT(?s) AS ?cnt) (AVG(?d1) AS ?distance)
FROM STREAM <{STREAM}> [RANGE 3s STEP 1s]
WHERE {{ ?s rdf:type printeps:Customer; printeps:positionAtTime ?t1, ?t2.
  ?t1 printeps:distance ?d1. ?t2 printeps:distance ?d2.
  BIND(?d2 - ?d1 AS ?difference)
  FILTER((f:timestamp(?s, printeps:positionAtTime, ?t1) > f:timestamp(?s, printeps:positionAtTime, ?t2))
         && 0.1 < ?difference) }}
GROUP BY ?s HAVING (AVG(?d1) < 3.5 && 1 < COUNT(?s))"""
HZ = 10
CUSTOMERS = 3
READINGS = 1_200  # 3,600 new position nodes: the table would hold them all without the bound
FLOOR = 256  # the table's floor for this test, below what one window needs (the window's own limit rules)
WINDOW_TRIPLES = 3 * HZ * CUSTOMERS * 3  # RANGE 3s of readings, three triples a customer


def reading(k: int) -> tuple[int, list[tuple]]:
    """The k-th reading: three customers of the party walking up to the entrance and away (a 10 s
    cycle), each position a node of its own, distances as exact decimals (the fast path decides)."""
    ts = 1_700_000_000_000 + k * 1000 // HZ
    phase = k % (10 * HZ)
    triples: list[tuple] = []
    for c in range(CUSTOMERS):
        who = NamedNode(f"{P}p{k // (10 * HZ)}c{c}")
        at = NamedNode(f"{who.value}_t{ts}")
        distance = Literal(f"{abs(5 * HZ - phase) / 10 + 1 + c / 10:.2f}", datatype=DECIMAL)
        triples += [(who, RDF_TYPE, NamedNode(P + "Customer")), (who, NamedNode(P + "positionAtTime"), at),
                    (at, NamedNode(P + "distance"), distance)]
    return ts, triples


def test_the_term_table_holds_what_the_windows_need_and_answers_stay_the_same(settings, monkeypatch) -> None:
    """The floor (4,096 terms in service) is lowered so that a two-minute stream passes it: the
    bound then comes from what a window holds, as it does on a busy stream."""
    monkeypatch.setattr(executor, "TERMS_FLOOR", FLOOR)
    fast = StreamEngine(settings)
    general = StreamEngine(StreamSettings(**{**settings.model_dump(), "fast_path": False}))
    for engine in (fast, general):
        engine.register(QUERY)
    runtime = fast._queries["Approaching"]
    assert runtime.plan is not None, runtime.not_compilable

    for k in range(READINGS):
        ts, triples = reading(k)
        fast.push(STREAM, ts, triples)
        general.push(STREAM, ts, triples)

    stats = runtime.stats
    assert stats["fast"] > 100 and stats["fallbacks"] == 0, stats  # the fast path ran on every window
    # the table is emptied past TERMS_SLACK x 2 terms a window's triple, and then holds at most that
    # and one window's new terms (two a triple)
    limit = max(FLOOR, executor.TERMS_SLACK * 2 * WINDOW_TRIPLES)
    assert len(runtime.plan.table) <= limit + 2 * WINDOW_TRIPLES, len(runtime.plan.table)
    assert runtime.plan.table.generation > 1  # it was emptied on the way
    fast_rows = [event["rows"] for event in fast.results("Approaching", limit=1000)]
    general_rows = [event["rows"] for event in general.results("Approaching", limit=1000)]
    assert fast_rows == general_rows
    assert sum(1 for rows in fast_rows if rows) > 20  # customers were detected: the answers were compared
