"""The fast path must return exactly the RDF terms pyoxigraph returns (datatypes and canonical
lexical forms included): query by query on random windows, and engine against engine on random
streams (hypothesis) with ties, empty groups, out-of-order and late messages."""

from __future__ import annotations

import random
from decimal import Decimal

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pyoxigraph import Literal, NamedNode

from gateway.config import StreamSettings
from gateway.rdf.terms import canonical_term
from gateway.stream import StreamEngine
from gateway.stream.evaluate import WindowData, evaluate_oxigraph, evaluate_rdflib
from gateway.stream.fastpath import Fallback, NotCompilable, compile_query, run_plan

P = "http://printeps.org/cafe/entrance/"
RDF_TYPE = NamedNode("http://www.w3.org/1999/02/22-rdf-syntax-ns#type")
XSD = "http://www.w3.org/2001/XMLSchema#"
PREFIXES = f"""PREFIX f: <http://larkc.eu/csparql/sparql/jena/ext#>
PREFIX rdf: <http://www.w3.org/1999/02/22-rdf-syntax-ns#>
PREFIX printeps: <{P}>
"""
TS1 = "f:timestamp(?s, printeps:positionAtTime, ?ts1)"
TS2 = "f:timestamp(?s, printeps:positionAtTime, ?ts2)"
PAIR = """?s rdf:type printeps:Customer; printeps:positionAtTime ?ts1, ?ts2.
?ts1 printeps:distance ?distance1. ?ts2 printeps:distance ?distance2."""
ONE = "?s printeps:positionAtTime ?t. ?t printeps:distance ?d."

COMPILABLE = {
    "published": f"""SELECT ?s (COUNT(?s) AS ?cnt) (AVG(?distance1) AS ?distance) WHERE {{ {PAIR}
        BIND(?distance2 - ?distance1 AS ?difference)
        FILTER(({TS1} > {TS2}) && 0.1 < ?difference) }}
        GROUP BY ?s HAVING (AVG(?distance1) < 3.3 && 1 < COUNT(?s))""",
    "leaving": f"""SELECT ?s (COUNT(*) AS ?n) (SUM(?distance1) AS ?sum) WHERE {{ {PAIR}
        BIND(?distance1 - ?distance2 AS ?d) FILTER({TS1} > {TS2} && ?d >= 0.05) }} GROUP BY ?s""",
    "single": """SELECT ?s (COUNT(*) AS ?n) (AVG(?d) AS ?avg) (MIN(?d) AS ?mn) (MAX(?d) AS ?mx) (SUM(?d) AS ?sum)
        WHERE { ?s a printeps:Customer; printeps:positionAtTime ?t. ?t printeps:distance ?d. FILTER(?d < 3) }
        GROUP BY ?s HAVING (COUNT(*) >= 2)""",
    "time-gap": f"""SELECT ?s (COUNT(?distance2) AS ?n) (MAX(?distance2) AS ?far) WHERE {{ {PAIR}
        FILTER({TS1} - {TS2} > 1500 && !(?distance1 > ?distance2)) }} GROUP BY ?s""",
    "or-not": f"""SELECT ?s (COUNT(?s) AS ?n) (AVG(?distance2) AS ?a) WHERE {{ {PAIR}
        FILTER(!(?distance1 > 3) || ?distance2 < 1.5) }} GROUP BY ?s HAVING (COUNT(?s) > 3 || AVG(?distance2) < 2)""",
    "having-arith": f"""SELECT ?s (SUM(?distance1) - SUM(?distance2) AS ?delta) (MAX(?distance1) AS ?m)
        WHERE {{ {PAIR} FILTER({TS1} != {TS2}) }} GROUP BY ?s
        HAVING (SUM(?distance1) - SUM(?distance2) > -0.5 && MAX(?distance1) * 2 < 7.5)""",
    "no-type": """SELECT ?s (COUNT(*) AS ?n) WHERE { ?s printeps:positionAtTime ?a, ?b. ?a printeps:distance ?x.
        ?b printeps:distance ?y. FILTER(?x - ?y = 0.25 || ?x = ?y) } GROUP BY ?s""",
    "bind-chain": f"""SELECT ?s (COUNT(*) AS ?n) (MIN(?y) AS ?lo) (AVG(?y) AS ?avg) WHERE {{ {PAIR}
        BIND(?distance2 - ?distance1 AS ?x) BIND(?x + 1 AS ?y) BIND(-?y AS ?z)
        FILTER(?y > 1.05 && ?z < 0 && {TS1} >= {TS2} + 0) }} GROUP BY ?s HAVING (MIN(?y) <= 3)""",
    "ts-const": f"""SELECT ?s (COUNT(*) AS ?n) WHERE {{ {PAIR} FILTER({TS1} >= 4000 && {TS2} < 2500) }} GROUP BY ?s""",
    "no-group": f"SELECT ?s ?d ?t WHERE {{ {ONE} }}",
    "bind-rows": f"SELECT ?s ?d (?d * 2 - 1 AS ?e) WHERE {{ {ONE} BIND(?d * 2 - 1 AS ?e0) FILTER(?e0 > 2) }}",
    "distinct": "SELECT DISTINCT ?s WHERE { ?s printeps:positionAtTime ?t }",
    "distinct-agg": f"SELECT ?s (COUNT(DISTINCT ?d) AS ?n) (COUNT(DISTINCT ?t) AS ?m) WHERE {{ {ONE} }} GROUP BY ?s",
    "multiply": f"SELECT ?s (COUNT(*) AS ?n) WHERE {{ {PAIR} FILTER(?distance1 * 2 > ?distance2) }} GROUP BY ?s",
    "implicit-group": f"""SELECT (COUNT(*) AS ?n) (SUM(?d) AS ?sum) (AVG(?d) AS ?avg) (MIN(?d) AS ?mn) (MAX(?d) AS ?mx)
        WHERE {{ {ONE} FILTER(?d > 2.5) }}""",
    "iri-compare": f"SELECT ?s (COUNT(*) AS ?n) WHERE {{ {ONE} ?s a ?k FILTER(?k != printeps:Staff) }} GROUP BY ?s ?k",
    "two-keys": f"SELECT ?s ?k (SUM(?d) AS ?sum) WHERE {{ {ONE} ?s a ?k }} GROUP BY ?s ?k",
    "having-div": f"SELECT ?s (SUM(?d) / COUNT(*) AS ?mean) WHERE {{ {ONE} }} GROUP BY ?s HAVING (SUM(?d) / 3 > 1)",
    # f:timestamp(a) op f:timestamp(b) becomes a band join: every operator, ties included
    "band-ge": f"SELECT ?s (COUNT(*) AS ?n) WHERE {{ {PAIR} FILTER({TS1} >= {TS2}) }} GROUP BY ?s",
    "band-lt": f"SELECT ?s (COUNT(*) AS ?n) (SUM(?distance2) AS ?x) WHERE {{ {PAIR} FILTER({TS1} < {TS2}) }} GROUP BY ?s",
    "band-le": f"SELECT ?s (COUNT(*) AS ?n) WHERE {{ {PAIR} FILTER({TS2} <= {TS1} && ?distance1 < 4) }} GROUP BY ?s",
    "ts-window": f"SELECT ?s (MAX(f:timestamp(?s, printeps:positionAtTime, ?t)) AS ?last) WHERE {{ {ONE} }} GROUP BY ?s",
}

NOT_COMPILABLE = {
    "order-by": "SELECT ?s (COUNT(*) AS ?n) WHERE { ?s printeps:positionAtTime ?t } GROUP BY ?s ORDER BY ?s",
    "optional": "SELECT ?s (COUNT(*) AS ?n) WHERE { ?s a printeps:Customer OPTIONAL { ?s printeps:age ?a } } GROUP BY ?s",
    "union": "SELECT ?s WHERE { { ?s a printeps:Customer } UNION { ?s a printeps:Staff } }",
    "limit": "SELECT ?s WHERE { ?s a printeps:Customer } LIMIT 3",
    "graph": "SELECT ?s WHERE { GRAPH <http://w> { ?s a printeps:Customer } }",
    "not-exists": "SELECT ?s WHERE { ?s a printeps:Customer FILTER NOT EXISTS { ?s printeps:age ?a } }",
    "variable-predicate": "SELECT ?p (COUNT(*) AS ?n) WHERE { ?s ?p ?o } GROUP BY ?p",
    "row-division": f"SELECT ?s WHERE {{ {ONE} FILTER(?d / 2 > 1) }}",
    "string-fn": f"SELECT ?s (COUNT(*) AS ?n) WHERE {{ {ONE} FILTER(STRSTARTS(STR(?s), \"x\")) }} GROUP BY ?s",
    "group-concat": f"SELECT ?s (GROUP_CONCAT(?d) AS ?all) WHERE {{ {ONE} }} GROUP BY ?s",
    "construct": "CONSTRUCT { ?s ?p ?o } WHERE { ?s ?p ?o }",
}

DECIMALS = ["0.5", "1", "1.0", "1.50", "1.5", "2.25", "2.5", "3", "3.00", "3.3", "4.05", "4.5"]  # ties, forms


def random_window(seed: int, integers: bool = False) -> WindowData:
    rnd = random.Random(seed)
    window = WindowData(0, 6000)
    for i in range(rnd.randint(0, 6)):
        s = NamedNode(f"{P}c{i}")
        kind = "Customer" if rnd.random() < 0.8 else "Staff"
        window.stamped[(s, RDF_TYPE, NamedNode(P + kind))] = 0
        for k in range(rnd.randint(0, 9)):
            ts = rnd.randrange(0, 6000, 250)
            node = NamedNode(f"{P}c{i}_r{k}")
            if integers:
                value = Literal(str(rnd.randint(0, 5)), datatype=NamedNode(XSD + "integer"))
            else:
                value = Literal(rnd.choice(DECIMALS), datatype=NamedNode(XSD + "decimal"))
            window.stamped[(s, NamedNode(P + "positionAtTime"), node)] = ts
            window.stamped[(node, NamedNode(P + "distance"), canonical_term(value))] = ts
            if rnd.random() < 0.1:  # a second value on the same reading
                extra = Literal(str(rnd.randint(1, 4)) + ".25", datatype=NamedNode(XSD + "decimal"))
                window.stamped[(node, NamedNode(P + "distance"), extra)] = ts
    return window


def terms(evaluation) -> list:
    """Rows as sorted (variable, canonical N-Triples term) lists: datatypes and lexical forms count."""
    return sorted(sorted((k, str(canonical_term(v))) for k, v in row.items()) for row in evaluation.rows)


@pytest.mark.parametrize("name", sorted(COMPILABLE))
def test_fast_path_returns_the_same_terms(name):
    query = PREFIXES + COMPILABLE[name]
    plan = compile_query(query)
    nonempty = fallbacks = 0
    for seed in range(40):
        window = random_window(seed, integers=seed % 5 == 0)
        try:
            fast = run_plan(plan, window)
        except Fallback:
            fallbacks += 1
            continue
        general = evaluate_oxigraph(query, window)
        assert terms(fast) == terms(general), f"seed {seed}"
        nonempty += bool(general.rows)
    assert nonempty >= 5, "the random data must exercise the query"
    assert fallbacks <= 4, "the fast path must decide (almost) every window itself"


@pytest.mark.parametrize("name", sorted(NOT_COMPILABLE))
def test_other_shapes_are_left_to_the_general_path(name):
    with pytest.raises(NotCompilable):
        compile_query(PREFIXES + NOT_COMPILABLE[name])


def test_data_it_cannot_decide_goes_the_general_way():
    query = PREFIXES + COMPILABLE["single"]
    plan = compile_query(query)
    window = random_window(3)
    node = NamedNode(P + "c0_rx")
    window.stamped[(NamedNode(P + "c0"), NamedNode(P + "positionAtTime"), node)] = 10
    window.stamped[(node, NamedNode(P + "distance"), Literal("1.5E0", datatype=NamedNode(XSD + "double")))] = 10
    with pytest.raises(Fallback, match="different kinds"):  # a double: not decided here
        run_plan(plan, window)
    tie = PREFIXES + "SELECT (MAX(?d) AS ?m) WHERE { ?t printeps:distance ?d }"
    window = WindowData(0, 1000, {(NamedNode(P + "a"), NamedNode(P + "distance"), Literal("3", datatype=NamedNode(XSD + "integer"))): 1,
                                  (NamedNode(P + "b"), NamedNode(P + "distance"), Literal("3", datatype=NamedNode(XSD + "decimal"))): 2})
    with pytest.raises(Fallback, match="tie between an integer and a decimal"):
        run_plan(compile_query(tie), window)


def test_rdflib_agrees_up_to_its_decimal_precision():
    query = PREFIXES + COMPILABLE["published"]
    plan = compile_query(query)

    def numbers(evaluation):
        return sorted(sorted((k, Decimal(v.value) if isinstance(v, Literal) else str(v)) for k, v in r.items())
                      for r in evaluation.rows)
    for seed in range(6):
        window = random_window(seed)
        fast, slow = numbers(run_plan(plan, window)), numbers(evaluate_rdflib(query, window))
        assert len(fast) == len(slow)
        for a, b in zip(fast, slow):
            for (ka, va), (kb, vb) in zip(a, b):
                assert ka == kb
                assert abs(va - vb) < Decimal("1e-15") if isinstance(va, Decimal) else va == vb


# -- engine against engine on random streams ------------------------------------------------------

STREAM = "http://printeps.org/cafe/entrance"
ENGINE_QUERIES = {
    name: f"REGISTER QUERY q AS\n{PREFIXES}" + COMPILABLE[name].replace(
        " WHERE", f" FROM STREAM <{STREAM}> [RANGE 2s STEP 500ms] FROM <http://printeps.org/cafe/ontology> WHERE", 1)
    for name in ("published", "single", "implicit-group", "two-keys", "distinct-agg", "no-group", "ts-window")
}
ENGINE_QUERIES["ontology-join"] = (
    f"REGISTER QUERY q AS\n{PREFIXES}SELECT ?table (COUNT(*) AS ?n) (MAX(?d) AS ?m) FROM STREAM <{STREAM}> "
    "[RANGE 2s STEP 500ms] FROM <http://printeps.org/cafe/ontology> WHERE { ?table a printeps:Table ; "
    "printeps:locationId ?loc . ?s printeps:location ?loc ; printeps:positionAtTime ?t . ?t printeps:distance ?d } "
    "GROUP BY ?table")
ENGINE_QUERIES["count-window"] = (
    f"REGISTER QUERY q AS\n{PREFIXES}SELECT (COUNT(*) AS ?n) (SUM(?d) AS ?sum) FROM STREAM <{STREAM}> "
    "[RANGE TRIPLES 7] WHERE { ?t printeps:distance ?d }")

value_st = st.one_of(st.sampled_from(DECIMALS).map(lambda v: ("decimal", v)),
                     st.integers(0, 5).map(lambda v: ("integer", str(v))))
reading_st = st.tuples(st.integers(0, 3), value_st, st.sampled_from(["Customer", "Staff", None]),
                       st.sampled_from(["table1", "table2", "nowhere"]))
message_st = st.tuples(st.integers(0, 24).map(lambda k: k * 250), st.lists(reading_st, max_size=4))


def _triples(k: int, readings: list) -> list:
    out = []
    for j, (who, (datatype, value), kind, loc) in enumerate(readings):
        s = NamedNode(f"{P}c{who}")
        node = NamedNode(f"{P}c{who}_m{k}_{j}")
        if kind:
            out.append((s, RDF_TYPE, NamedNode(P + kind)))
        out.append((s, NamedNode(P + "location"), Literal(loc)))
        out.append((s, NamedNode(P + "positionAtTime"), node))
        out.append((node, NamedNode(P + "distance"), Literal(value, datatype=NamedNode(XSD + datatype))))
    return out


def _replay(query: str, messages: list, fast: bool) -> tuple[list, dict]:
    engine = StreamEngine(StreamSettings(queries_dir=None, fast_path=fast))
    info = engine.register(query)
    assert info["fast_path"] is fast, info["not_compilable"]
    events: list = []
    engine.subscribe(events.append)
    for k, (ts, readings) in enumerate(messages):
        engine.push(STREAM, ts, _triples(k, readings))
    engine.advance(8000)
    out = [(e["window"], e.get("skipped"), [sorted((v, str(t)) for v, t in row.items()) for row in e.terms])
           for e in events if e["kind"] == "result"]
    return out, engine.query_info("q")["stats"]


@pytest.mark.parametrize("name", sorted(ENGINE_QUERIES))
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(messages=st.lists(message_st, min_size=1, max_size=14))
def test_both_paths_report_identical_windows(name, messages):
    # timestamps are drawn unsorted: some messages arrive out of order, some late (then dropped by both)
    fast, fast_stats = _replay(ENGINE_QUERIES[name], messages, True)
    general, general_stats = _replay(ENGINE_QUERIES[name], messages, False)
    assert fast == general
    assert fast_stats["late_dropped"] == general_stats["late_dropped"]
    assert fast_stats["general"] == fast_stats["fallbacks"]  # only data it cannot decide left the fast path


def test_large_groups_stay_on_the_fast_path():
    # 6,000 readings of one person: the static bound of a sum (10**15 units a value) would overflow
    # int64; the measured one does not, so the window is still decided by the fast path
    query = PREFIXES + "SELECT ?s (SUM(?d) AS ?sum) (AVG(?d) AS ?avg) WHERE { ?s printeps:positionAtTime ?t . ?t printeps:distance ?d } GROUP BY ?s"
    window = WindowData(0, 10_000)
    s = NamedNode(P + "c1")
    for k in range(6000):
        node = NamedNode(f"{P}r{k}")
        window.stamped[(s, NamedNode(P + "positionAtTime"), node)] = k
        window.stamped[(node, NamedNode(P + "distance"), Literal(f"{k % 7}.25", datatype=NamedNode(XSD + "decimal")))] = k
    fast = run_plan(compile_query(query), window)
    assert terms(fast) == terms(evaluate_oxigraph(query, window))


def test_empty_windows_after_a_fallback_are_counted_as_the_path_that_answered():
    # a reading with a double falls back; the empty windows after it are first left to the general
    # path (the back-off) and then tried fast again: a general answer kept for every later empty
    # window made "general" exceed "fallbacks" (16 against 5 here)
    _, stats = _replay(ENGINE_QUERIES["single"], [(0, [(1, ("double", "1.5"), "Customer", "table1")]), (250, [])], True)
    assert stats["general"] == stats["fallbacks"] and stats["fast"] > 0, stats
