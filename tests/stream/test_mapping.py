"""Messages → RDF: the entrance mapping, the generic default, and errors that name the field."""

from __future__ import annotations

from types import SimpleNamespace

import pytest
from pyoxigraph import BlankNode, Literal, NamedNode

from pathlib import Path

from gateway.rdf import Mapper, MappingError, TermError, parse_triple
from gateway.rdf.mapping import mappings_from_folder
from gateway.rdf.terms import RDF_TYPE, XSD_DECIMAL, XSD_INTEGER

P = "http://printeps.org/cafe/entrance/"
TEAHOUSE = mappings_from_folder(Path(__file__).resolve().parents[2] / "ontology" / "mappings")


def teahouse_mapper() -> Mapper:
    """A mapper with the teahouse's mappings as the repository ships them (data, not code)."""
    return Mapper(TEAHOUSE)


def n(local: str) -> NamedNode:
    return NamedNode(P + local)


def test_entrance_message_matches_the_papers_rdf_stream():
    msg = {"id": "e1", "number_of_customers": 1, "customers": [{"id": "c1", "distance": 2.5, "age": 30}]}
    triples = set(teahouse_mapper().map(msg, 1500, "entrance"))
    assert {
        (n("c1"), RDF_TYPE, n("Customer")),
        (n("c1"), n("positionAtTime"), n("c1_t1500")),
        (n("c1_t1500"), n("distance"), Literal("2.5", datatype=XSD_DECIMAL)),
        (n("c1"), n("age"), Literal("30", datatype=XSD_INTEGER)),
        (n("entrance_e1"), n("hasCustomer"), n("c1")),
        (n("entrance_e1"), n("numberOfCustomers"), Literal("1", datatype=XSD_INTEGER)),
    } <= triples


class FakeRosMessage(SimpleNamespace):
    """Quacks like an rclpy message (get_fields_and_field_types)."""

    def get_fields_and_field_types(self):
        return {k: "?" for k in vars(self)}


def test_ros_message_objects_are_mapped_like_dicts():
    msg = FakeRosMessage(id="e1", number_of_customers=1,
                         customers=[FakeRosMessage(id="c9", distance=1.25, age=7, gender="female")])
    triples = teahouse_mapper().map(msg, 10, "entrance")
    assert (n("c9_t10"), n("distance"), Literal("1.25", datatype=XSD_DECIMAL)) in triples


def test_generic_default_uses_field_names():
    triples = teahouse_mapper().map({"id": "cup1", "level": 0.25, "tags": ["a", "b"], "pos": {"x": 1}}, 0)
    assert (n("cup1"), n("level"), Literal("0.25", datatype=XSD_DECIMAL)) in triples
    assert (n("cup1"), n("tags"), Literal("b")) in triples
    (pos,) = [o for s, p, o in triples if p == n("pos")]
    assert isinstance(pos, BlankNode) and (pos, n("x"), Literal("1", datatype=XSD_INTEGER)) in triples


@pytest.mark.parametrize("msg, mapping, where", [
    ({"customers": [{"id": "c1"}], "number_of_customers": 1}, "entrance", "message.id"),
    ({"id": "e", "customers": [{"id": "c1"}, {"distance": 1.0}]}, "entrance", "message.customers[1].id"),
    ({"id": "e", "customers": [{"id": "c1", "distance": {"x": 1}}]}, "entrance", "message.customers[0].distance"),
    ({"id": "e", "customers": [{"id": "c1", "distance": float("nan")}]}, "entrance", "message.customers[0].distance"),
    ({"id": "x"}, "nope", "mapping"),
    ({"id": "x", "l": [[1]]}, None, "message.l[0]"),
])
def test_bad_messages_name_the_field(msg, mapping, where):
    with pytest.raises(MappingError) as info:
        teahouse_mapper().map(msg, 0, mapping)
    assert info.value.where == where


def test_rest_triples():
    s, p, o = parse_triple(["printeps:c1", "<http://x/p>", 2.5], "triples[0]")
    assert (s, p, o) == (n("c1"), NamedNode("http://x/p"), Literal("2.5", datatype=XSD_DECIMAL))
    assert parse_triple(["_:b", "rdf:type", {"value": "3", "datatype": "xsd:integer"}], "t")[2] == \
        Literal("3", datatype=XSD_INTEGER)
    for bad, where in ([["a"], "t"], [["zz:c", "rdf:type", "x:y"], "t[0]"], [["printeps:a", "_:b", 1], "t[1]"],
                       [["printeps:a", "rdf:type", None], "t[2]"], [["not an iri", "rdf:type", 1], "t[0]"]):
        with pytest.raises(TermError) as info:
            parse_triple(bad, "t")
        assert info.value.where == where
