"""Results as RDF terms: XSD canonical forms, SPARQL 1.1 Query Results JSON, the push report."""

from __future__ import annotations

import json

import pytest
from pyoxigraph import BlankNode, Literal, NamedNode

from gateway.rdf.terms import canonical_term, term_from_sparql_json, term_to_sparql_json
from gateway.stream import StreamEngine, report_to_sparql_json, to_sparql_json

XSD = "http://www.w3.org/2001/XMLSchema#"
EX = "http://ex/"
S = "http://ex/s"


def lit(value: str, datatype: str) -> Literal:
    return Literal(value, datatype=NamedNode(XSD + datatype))


@pytest.mark.parametrize("given, canonical", [
    (("03", "integer"), ("3", "integer")),
    (("+5", "int"), ("5", "integer")),          # integer-derived types are stored as xsd:integer
    (("-0", "long"), ("0", "integer")),
    (("3.10", "decimal"), ("3.1", "decimal")),
    (("3.0", "decimal"), ("3", "decimal")),     # XSD 1.1: no decimal point for integral values
    (("-.50", "decimal"), ("-0.5", "decimal")),
    (("1", "boolean"), ("true", "boolean")),
    (("10", "double"), ("1.0E1", "double")),
    (("0.001", "double"), ("1.0E-3", "double")),
    (("-0", "double"), ("-0.0E0", "double")),
    (("INF", "double"), ("INF", "double")),
    (("0.1", "float"), ("1.0E-1", "float")),
    (("abc", "integer"), ("abc", "integer")),   # ill-typed: left as it is
])
def test_xsd_canonical_forms(given, canonical):
    assert canonical_term(lit(*given)) == lit(*canonical)


def test_sparql_json_terms():
    assert term_to_sparql_json(NamedNode(EX + "a")) == {"type": "uri", "value": EX + "a"}
    assert term_to_sparql_json(BlankNode("b1")) == {"type": "bnode", "value": "b1"}
    assert term_to_sparql_json(Literal("x")) == {"type": "literal", "value": "x"}
    assert term_to_sparql_json(Literal("x", language="en")) == {"type": "literal", "value": "x", "xml:lang": "en"}
    assert term_to_sparql_json(lit("43", "double")) == {"type": "literal", "value": "43", "datatype": XSD + "double"}
    for term in (NamedNode(EX + "a"), BlankNode("b1"), Literal("x"), Literal("x", language="en"), lit("4.5", "decimal")):
        assert term_from_sparql_json(term_to_sparql_json(term)) == term


def _engine(settings, fast: bool) -> StreamEngine:
    engine = StreamEngine(settings.model_copy(update={"fast_path": fast}))
    engine.register(f"REGISTER QUERY q AS PREFIX ex: <{EX}>\nSELECT ?s (SUM(?v) AS ?sum) (MAX(?v) AS ?max) "
                    f"(AVG(?v) AS ?avg) (COUNT(*) AS ?n) FROM STREAM <{S}> [RANGE 1s STEP 1s] WHERE {{ ?s ex:v ?v }} "
                    "GROUP BY ?s")
    return engine


@pytest.mark.parametrize("fast", [True, False], ids=["fast-path", "general"])
def test_datatypes_are_exact_on_both_paths(settings, fast):
    engine = _engine(settings, fast)
    report = engine.push(S, 10, [(NamedNode(EX + "a"), NamedNode(EX + "v"), lit("40", "integer")),
                                 (NamedNode(EX + "a"), NamedNode(EX + "v"), lit("3", "integer"))], with_results=True)
    assert report["results"] == []  # nothing closed yet
    report = engine.push(S, 1000, [], with_results=True)
    (event,) = report["results"]
    assert event["path"] == ("fast" if fast else "oxigraph")
    assert event["rows"] == [{"s": EX + "a", "sum": 43, "max": 40, "avg": 21.5, "n": 2}]  # plain JSON: the default
    doc = to_sparql_json(event)
    assert doc["head"] == {"vars": ["s", "sum", "max", "avg", "n"]}
    assert doc["results"]["bindings"] == [{
        "s": {"type": "uri", "value": EX + "a"},
        "sum": {"type": "literal", "value": "43", "datatype": XSD + "integer"},  # not xsd:decimal
        "max": {"type": "literal", "value": "40", "datatype": XSD + "integer"},
        "avg": {"type": "literal", "value": "21.5", "datatype": XSD + "decimal"},
        "n": {"type": "literal", "value": "2", "datatype": XSD + "integer"},
    }]
    assert doc["window"] == {"start": 0, "end": 1000, "triples": 2} and doc["query"] == "q" and "rows" not in doc
    assert report_to_sparql_json(report)["results"] == [doc]
    assert json.loads(json.dumps(event)) == dict(event)  # the terms are not part of the JSON


def test_a_double_is_not_a_decimal_and_an_iri_is_not_a_string(engine):
    engine.register(f"REGISTER QUERY q AS PREFIX ex: <{EX}>\nSELECT ?v FROM STREAM <{S}> [RANGE 1s STEP 1s] "
                    "WHERE { ?s ex:v ?v }")
    events: list[dict] = []
    engine.subscribe(events.append)
    values = [lit("43", "double"), lit("43.0", "decimal"), NamedNode(EX + "x"), Literal(EX + "x"),
              Literal("hi", language="en"), BlankNode("n1")]
    engine.push(S, 10, [(NamedNode(f"{EX}s{i}"), NamedNode(EX + "v"), v) for i, v in enumerate(values)])
    engine.advance(1000)
    (event,) = events
    got = sorted(json.dumps(b["v"], sort_keys=True) for b in to_sparql_json(event)["results"]["bindings"])
    assert got == sorted(json.dumps(x, sort_keys=True) for x in [
        {"type": "literal", "value": "4.3E1", "datatype": XSD + "double"},
        {"type": "literal", "value": "43", "datatype": XSD + "decimal"},
        {"type": "uri", "value": EX + "x"},
        {"type": "literal", "value": EX + "x"},
        {"type": "literal", "value": "hi", "xml:lang": "en"},
        {"type": "bnode", "value": "n1"},
    ])


def test_ask_and_construct_in_sparql_json(engine):
    engine.register(f"REGISTER QUERY a AS PREFIX ex: <{EX}>\nASK FROM STREAM <{S}> [RANGE 1s STEP 1s] WHERE {{ ?s ex:v 1 }}")
    engine.register(f"REGISTER STREAM ex:c AS PREFIX ex: <{EX}>\nCONSTRUCT {{ ?s ex:seen ?v }} FROM STREAM <{S}> "
                    "[RANGE 1s STEP 1s] WHERE { ?s ex:v ?v }")
    report = engine.push(S, 10, [(NamedNode(EX + "a"), NamedNode(EX + "v"), lit("1", "integer"))])
    report = engine.push(S, 1000, [], with_results=True)
    docs = {e["query"]: to_sparql_json(e) for e in report["results"]}
    assert docs["a"]["head"] == {} and docs["a"]["boolean"] is True and "results" not in docs["a"]
    assert docs["ex:c"]["head"] == {"vars": ["subject", "predicate", "object"]}
    assert docs["ex:c"]["results"]["bindings"] == [{
        "subject": {"type": "uri", "value": EX + "a"}, "predicate": {"type": "uri", "value": EX + "seen"},
        "object": {"type": "literal", "value": "1", "datatype": XSD + "integer"}}]
    assert report["derived"] == 1


def test_other_events_pass_and_foreign_results_are_refused():
    assert to_sparql_json({"kind": "error", "query": "q", "error": "x"}) == {"kind": "error", "query": "q", "error": "x"}
    with pytest.raises(ValueError, match="no RDF terms"):
        to_sparql_json({"kind": "result", "rows": []})
