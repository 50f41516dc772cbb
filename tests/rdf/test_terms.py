"""gateway/rdf/terms.py on its own: JSON values ↔ RDF terms, node and triple parsing with errors
that name the element, XSD 1.1 canonical forms, and the SPARQL JSON form of a term."""

from __future__ import annotations

import math
from decimal import Decimal

import pytest
from pyoxigraph import BlankNode, Literal, NamedNode

from gateway.rdf.terms import (PRINTEPS, XSD, XSD_BOOLEAN, XSD_DECIMAL, XSD_DOUBLE, XSD_FLOAT, XSD_INTEGER,
                               TermError, canonical_decimal, canonical_double, canonical_term, canonical_triple,
                               decimal_literal, local_name, parse_node, parse_object, parse_triple,
                               term_from_sparql_json, term_to_json, term_to_sparql_json, value_to_term)


def lit(value: str, datatype: str) -> Literal:
    return Literal(value, datatype=NamedNode(XSD + datatype))


@pytest.mark.parametrize("value, expected", [
    (True, Literal("true", datatype=XSD_BOOLEAN)),
    (False, Literal("false", datatype=XSD_BOOLEAN)),  # a bool is not taken for the int it also is
    (7, Literal("7", datatype=XSD_INTEGER)),
    (2.5, Literal("2.5", datatype=XSD_DECIMAL)),
    (0.1, Literal("0.1", datatype=XSD_DECIMAL)),  # through repr: not 0.1000000000000000055…
    (3.0, Literal("3", datatype=XSD_DECIMAL)),
    (Decimal("2.50"), Literal("2.5", datatype=XSD_DECIMAL)),
    ("hi", Literal("hi")),
])
def test_json_values_become_exact_literals(value, expected):
    assert value_to_term(value) == expected


@pytest.mark.parametrize("value, said", [
    (math.nan, "nan is not a finite number"),
    (math.inf, "inf is not a finite number"),
    ([1], "a list cannot be an RDF literal"),
    (None, "a NoneType cannot be an RDF literal"),
])
def test_values_that_cannot_be_literals_are_refused_naming_the_place(value, said):
    with pytest.raises(TermError) as err:
        value_to_term(value, "customers[2].distance")
    assert err.value.where == "customers[2].distance" and said in err.value.message


def test_decimal_literal_keeps_the_decimal_digits_and_drops_trailing_zeros():
    assert decimal_literal("2.500").value == "2.5"
    assert decimal_literal(10).value == "10"
    assert decimal_literal(1e-7).value == "0.0000001"  # never exponent notation in xsd:decimal


@pytest.mark.parametrize("text, iri", [
    ("<http://x.org/a>", "http://x.org/a"),
    ("printeps:Customer", PRINTEPS + "Customer"),
    ("xsd:decimal", XSD + "decimal"),
    ("http://x.org/b#c", "http://x.org/b#c"),
    ("<urn:uuid:1234>", "urn:uuid:1234"),  # bare, "urn:" reads as a prefix (refused below)
])
def test_nodes_are_read_in_each_written_form(text, iri):
    assert parse_node(text, "s") == NamedNode(iri)


def test_a_blank_node_and_custom_prefixes():
    assert parse_node("_:b1", "s") == BlankNode("b1")
    assert parse_node("ex:thing", "s", {"ex": "http://example.org/"}) == NamedNode("http://example.org/thing")


@pytest.mark.parametrize("text, said", [
    ("", "expected an IRI string"),
    (42, "expected an IRI string"),
    ("nope:thing", "unknown prefix 'nope'"),
    ("urn:uuid:1234", "unknown prefix 'urn'"),
    ("<not an iri>", "invalid IRI"),
    ("just words", "is not an IRI"),
])
def test_bad_nodes_name_the_place_and_the_problem(text, said):
    with pytest.raises(TermError) as err:
        parse_node(text, "triples[3][0]")
    assert err.value.where == "triples[3][0]" and said in err.value.message
    assert str(err.value).startswith("triples[3][0]: ")


@pytest.mark.parametrize("raw, expected", [
    ({"value": "3", "datatype": "xsd:integer"}, Literal("3", datatype=XSD_INTEGER)),
    ({"value": True, "datatype": "xsd:boolean"}, Literal("true", datatype=XSD_BOOLEAN)),
    ({"value": "Hallo", "lang": "de"}, Literal("Hallo", language="de")),
    ({"value": "plain"}, Literal("plain")),
    ('"quoted text"', Literal("quoted text")),
    ("printeps:c1", NamedNode(PRINTEPS + "c1")),
    (1.8, Literal("1.8", datatype=XSD_DECIMAL)),
])
def test_objects_in_each_json_form(raw, expected):
    assert parse_object(raw, "o") == expected


def test_triples_are_checked_element_by_element():
    s, p, o = parse_triple(["printeps:c1", "printeps:age", 30], "triples[0]")
    assert (s, p, o) == (NamedNode(PRINTEPS + "c1"), NamedNode(PRINTEPS + "age"), Literal("30", datatype=XSD_INTEGER))
    for raw, where, said in [
        (["a:b", "printeps:x"], "triples[1]", "a triple must be a list"),
        ("printeps:c1 printeps:age 30", "triples[1]", "a triple must be a list"),
        (["printeps:c1", "_:p", 1], "triples[1][1]", "a predicate cannot be a blank node"),
        (["printeps:c1", "printeps:age", {"datatype": "xsd:integer"}], "triples[1][2]", "needs a 'value'"),
        (["printeps:c1", "printeps:age", [1]], "triples[1][2]", "cannot be an RDF literal"),
        (["bad iri", "printeps:age", 1], "triples[1][0]", "is not an IRI"),
    ]:
        with pytest.raises(TermError) as err:
            parse_triple(raw, "triples[1]")
        assert (err.value.where, said in err.value.message) == (where, True), (raw, err.value)


@pytest.mark.parametrize("term, expected", [
    (lit("03", "integer"), lit("3", "integer")),
    (lit("+7", "int"), lit("7", "integer")),  # integer-derived types are stored as xsd:integer
    (lit("3.10", "decimal"), lit("3.1", "decimal")),
    (lit("3.0", "decimal"), lit("3", "decimal")),
    (lit("-.5", "decimal"), lit("-0.5", "decimal")),
    (lit("1", "boolean"), lit("true", "boolean")),
    (lit("0", "boolean"), lit("false", "boolean")),
    (lit("10", "double"), lit("1.0E1", "double")),
    (lit("0.00125", "double"), lit("1.25E-3", "double")),
    (lit("-0", "double"), lit("-0.0E0", "double")),
    (lit("INF", "double"), lit("INF", "double")),
    (lit("0.1", "float"), lit("1.0E-1", "float")),
    (lit("abc", "integer"), lit("abc", "integer")),  # ill-typed: left as it is
    (Literal("x", language="en"), Literal("x", language="en")),
    (NamedNode("http://x.org/a"), NamedNode("http://x.org/a")),
])
def test_canonical_forms(term, expected):
    assert canonical_term(term) == expected
    assert canonical_term(canonical_term(term)) == expected  # canonical forms are fixed points


def test_canonical_helpers_and_triples():
    assert canonical_decimal(Decimal("-0.50")) == "-0.5" and canonical_decimal(Decimal("4.000")) == "4"
    assert canonical_double(float("nan")) == "NaN" and canonical_double(-math.inf) == "-INF"
    triple = (NamedNode("http://x.org/s"), NamedNode("http://x.org/p"), lit("05", "integer"))
    assert canonical_triple(triple)[2] == lit("5", "integer")
    assert canonical_triple((triple[0], triple[1], Literal("x"))) == (triple[0], triple[1], Literal("x"))


@pytest.mark.parametrize("term, value", [
    (lit("7", "integer"), 7),
    (lit("2.5", "decimal"), 2.5),
    (lit("1.0E1", "double"), 10.0),
    (lit("true", "boolean"), True),
    (Literal("hi"), "hi"),
    (NamedNode(PRINTEPS + "c1"), PRINTEPS + "c1"),
    (BlankNode("b"), "_:b"),
    (None, None),
])
def test_terms_as_json_values(term, value):
    got = term_to_json(term)
    assert got == value and type(got) is type(value)


@pytest.mark.parametrize("term", [
    NamedNode("http://x.org/a"), BlankNode("b0"), Literal("plain"), Literal("Hallo", language="de"),
    lit("2.5", "decimal"), lit("1.0E1", "double"), Literal("x", datatype=XSD_FLOAT),
])
def test_sparql_json_round_trips(term):
    data = term_to_sparql_json(term)
    assert term_from_sparql_json(data) == term
    if isinstance(term, Literal) and (term.language or term.datatype.value == XSD + "string"):
        assert "datatype" not in data  # simple and language-tagged literals carry no datatype


def test_sparql_json_refuses_what_is_not_a_term():
    with pytest.raises(ValueError, match="not a SPARQL JSON term"):
        term_from_sparql_json({"type": "triple", "value": "x"})
    assert term_to_sparql_json(lit("7", "integer")) == {"type": "literal", "value": "7", "datatype": XSD + "integer"}
    assert term_to_sparql_json(Literal("x", datatype=XSD_DOUBLE))["datatype"] == XSD + "double"


@pytest.mark.parametrize("iri, name", [
    (PRINTEPS + "c1", "c1"), ("http://x.org/o#Customer", "Customer"), ("urn:x", "urn:x"), ("http://x.org/", "http://x.org/"),
])
def test_local_name(iri, name):
    assert local_name(iri) == name
