"""The vectorised path must return exactly what pyoxigraph returns, on many queries and random data."""

from __future__ import annotations

import random
from decimal import Decimal

import pytest
from pyoxigraph import Literal, NamedNode

from gateway.stream.evaluate import WindowData, evaluate_oxigraph, evaluate_rdflib
from gateway.stream.fastpath import NotCompilable, compile_query, run_plan

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
}

NOT_COMPILABLE = {
    "order-by": "SELECT ?s (COUNT(*) AS ?n) WHERE { ?s printeps:positionAtTime ?t } GROUP BY ?s ORDER BY ?s",
    "optional": "SELECT ?s (COUNT(*) AS ?n) WHERE { ?s a printeps:Customer OPTIONAL { ?s printeps:age ?a } } GROUP BY ?s",
    "no-group": "SELECT ?s ?d WHERE { ?s printeps:positionAtTime ?t. ?t printeps:distance ?d }",
    "distinct-agg": """SELECT ?s (COUNT(DISTINCT ?d) AS ?n) WHERE { ?s printeps:positionAtTime ?t.
        ?t printeps:distance ?d } GROUP BY ?s""",
    "multiply": f"""SELECT ?s (COUNT(*) AS ?n) WHERE {{ {PAIR} FILTER(?distance1 * 2 > ?distance2) }} GROUP BY ?s""",
    "string-fn": """SELECT ?s (COUNT(*) AS ?n) WHERE { ?s printeps:positionAtTime ?t. ?t printeps:distance ?d
        FILTER(STRSTARTS(STR(?s), "x")) } GROUP BY ?s""",
    "construct": "CONSTRUCT { ?s ?p ?o } WHERE { ?s ?p ?o }",
}


def random_window(seed: int, integers: bool = False) -> WindowData:
    rnd = random.Random(seed)
    window = WindowData(0, 6000)
    for i in range(rnd.randint(1, 6)):
        s = NamedNode(f"{P}c{i}")
        kind = "Customer" if rnd.random() < 0.8 else "Staff"
        window.stamped[(s, RDF_TYPE, NamedNode(P + kind))] = 0
        for k in range(rnd.randint(0, 9)):
            ts = rnd.randrange(0, 6000, 250)
            node = NamedNode(f"{P}c{i}_r{k}")
            if integers:
                value = Literal(str(rnd.randint(0, 5)), datatype=NamedNode(XSD + "integer"))
            else:
                value = Literal(str(Decimal(rnd.randint(50, 450)) / 100), datatype=NamedNode(XSD + "decimal"))
            window.stamped[(s, NamedNode(P + "positionAtTime"), node)] = ts
            window.stamped[(node, NamedNode(P + "distance"), value)] = ts
            if rnd.random() < 0.1:  # a second value on the same reading
                extra = Literal(str(rnd.randint(1, 4)) + ".25", datatype=NamedNode(XSD + "decimal"))
                window.stamped[(node, NamedNode(P + "distance"), extra)] = ts
    return window


def canonical(evaluation) -> list:
    def value(term):
        if isinstance(term, Literal) and term.datatype.value in (XSD + "decimal", XSD + "integer"):
            return ("number", Decimal(term.value))
        return ("term", str(term))
    return sorted(sorted((k, value(v)) for k, v in row.items()) for row in evaluation.rows)


@pytest.mark.parametrize("name", sorted(COMPILABLE))
def test_fast_path_equals_pyoxigraph(name):
    query = PREFIXES + COMPILABLE[name]
    plan = compile_query(query)
    nonempty = 0
    for seed in range(40):
        window = random_window(seed, integers=seed % 5 == 0)
        fast, general = run_plan(plan, window), evaluate_oxigraph(query, window)
        assert canonical(fast) == canonical(general), f"seed {seed}"
        nonempty += bool(general.rows)
    assert nonempty >= 5, "the random data must exercise the query"


@pytest.mark.parametrize("name", sorted(NOT_COMPILABLE))
def test_other_shapes_are_left_to_the_general_path(name):
    with pytest.raises(NotCompilable):
        compile_query(PREFIXES + NOT_COMPILABLE[name])


def test_rdflib_agrees_up_to_its_decimal_precision():
    query = PREFIXES + COMPILABLE["published"]
    plan = compile_query(query)
    for seed in range(6):
        window = random_window(seed)
        fast, slow = canonical(run_plan(plan, window)), canonical(evaluate_rdflib(query, window))
        assert len(fast) == len(slow)
        for a, b in zip(fast, slow):
            for (ka, (kind, va)), (kb, (_, vb)) in zip(a, b):
                assert ka == kb
                assert abs(va - vb) < Decimal("1e-15") if kind == "number" else va == vb
