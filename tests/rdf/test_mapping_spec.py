"""gateway/rdf/mapping.py on its own: mappings as data (read, written back, errors naming the key),
checked against rosidl message types, derived from a type alone, and the mapper's edge cases
(blank nodes, timed readings, lists, depth and IRI-unsafe ids). tests/stream/test_mapping.py covers
the entrance mapping the papers use."""

from __future__ import annotations

import pytest
import yaml
from pyoxigraph import BlankNode, Literal, NamedNode

from gateway.config import PROJECT_ROOT
from gateway.rdf.mapping import (MAX_DEPTH, Mapper, MappingError, NodeMap, check_against, element_type,
                                 introspected_spec, is_message_type, message_to_dict, node_map_from_spec, spec_of)
from gateway.rdf.terms import PRINTEPS, RDF_TYPE, XSD_DECIMAL, XSD_INTEGER

TYPES = {
    "printeps_interfaces/msg/Entrance": {"id": "string", "number_of_customers": "int32",
                                         "customers": "sequence<printeps_interfaces/Customer>",
                                         "stamp": "builtin_interfaces/Time"},
    "printeps_interfaces/msg/Customer": {"id": "string", "distance": "float64", "age": "int32",
                                         "gender": "string<10>", "tags": "sequence<string>"},
}


# The papers' entrance stream shape, which the shipped ontology/mappings/entrance.yaml must give.
CUSTOMER = NodeMap(subject="printeps:{id}", rdf_type="printeps:Customer",
                   fields={"age": "printeps:age", "gender": "printeps:gender"}, timed={"distance": "printeps:distance"})
ENTRANCE = NodeMap(subject="printeps:entrance_{id}", rdf_type="printeps:EntranceObservation",
                   fields={"number_of_customers": "printeps:numberOfCustomers"},
                   children={"customers": ("printeps:hasCustomer", CUSTOMER)})


def describe(type_name: str) -> dict[str, str]:
    return TYPES[type_name]


def p(local: str) -> NamedNode:
    return NamedNode(PRINTEPS + local)


def test_the_shipped_entrance_mapping_has_the_papers_shape_and_round_trips():
    spec = yaml.safe_load((PROJECT_ROOT / "ontology" / "mappings" / "entrance.yaml").read_text())
    node = node_map_from_spec(spec)
    assert node == ENTRANCE
    assert node_map_from_spec(spec_of(node)) == node


@pytest.mark.parametrize("spec, where, said", [
    ([], "mapping", "a mapping must be an object"),
    ({"subjekt": "printeps:{id}"}, "mapping.subjekt", "unknown key"),
    ({"subject": 3}, "mapping.subject", "IRI template"),
    ({"type": "nope:Thing"}, "mapping.type", "unknown prefix 'nope'"),
    ({"fields": ["age"]}, "mapping.fields", "must map message fields to predicates"),
    ({"fields": {"age": ""}}, "mapping.fields.age", "non-empty text"),
    ({"timed": {"distance": "bad iri"}}, "mapping.timed.distance", "is not an IRI"),
    ({"children": {"customers": {"type": "printeps:Customer"}}}, "mapping.children.customers", "needs 'link'"),
    ({"children": {"customers": {"link": "printeps:has", "fields": {"x": "nope:x"}}}},
     "mapping.children.customers.fields.x", "unknown prefix"),
    ({"children": {"customers": {"link": "printeps:has", "mapping": "unknown"}}},
     "mapping.children.customers.mapping", "no mapping named 'unknown'"),
])
def test_bad_specs_name_the_key(spec, where, said):
    with pytest.raises(MappingError) as err:
        node_map_from_spec(spec)
    assert err.value.where == where and said in err.value.message, (err.value.where, err.value.message)


def test_a_child_can_reuse_a_named_mapping():
    node = node_map_from_spec({"subject": "printeps:g_{id}", "children": {"people": {"link": "printeps:has",
                                                                                    "mapping": "customer"}}},
                              resolve={"customer": ENTRANCE.children["customers"][1]})
    assert node.children["people"] == ("printeps:has", ENTRANCE.children["customers"][1])


def test_custom_prefixes_are_used_in_specs_and_mapping():
    spec = {"subject": "ex:{id}", "type": "ex:Robot", "fields": {"battery": "ex:battery"}}
    node = node_map_from_spec(spec, prefixes={"ex": "http://example.org/"})
    triples = Mapper({"robot": node}, prefixes={"ex": "http://example.org/"}).map({"id": "r1", "battery": 80}, 0, "robot")
    assert set(triples) == {(NamedNode("http://example.org/r1"), RDF_TYPE, NamedNode("http://example.org/Robot")),
                            (NamedNode("http://example.org/r1"), NamedNode("http://example.org/battery"),
                             Literal("80", datatype=XSD_INTEGER))}


def test_a_mapping_without_a_subject_makes_blank_nodes_and_timed_values_hang_off_a_reading():
    node = NodeMap(subject=None, rdf_type="printeps:Reading", timed={"d": "printeps:distance"})
    triples = Mapper({"r": node}).map({"d": 1.5}, 2000, "r")
    subject, reading = triples[0][0], triples[1][2]
    assert isinstance(subject, BlankNode) and isinstance(reading, BlankNode)
    assert triples == [(subject, RDF_TYPE, p("Reading")), (subject, p("positionAtTime"), reading),
                       (reading, p("distance"), Literal("1.5", datatype=XSD_DECIMAL))]


def test_list_fields_and_unsafe_ids():
    node = NodeMap(subject="printeps:{id}", fields={"tags": "printeps:tag"})
    triples = Mapper({"x": node}).map({"id": "a b/é", "tags": ["x", "y"]}, 0, "x")
    assert triples == [(p("a%20b%2F%C3%A9"), p("tag"), Literal("x")), (p("a%20b%2F%C3%A9"), p("tag"), Literal("y"))]


@pytest.mark.parametrize("message, mapping, where, said", [
    ({"number_of_customers": 1}, "entrance", "message.id", "missing (needed to name the node)"),
    ({"id": "e", "customers": [{"id": "c", "age": {"years": 3}}]}, "entrance", "message.customers[0].age",
     "expected a scalar"),
    ({"id": "e", "customers": ["c1"]}, "entrance", "message.customers[0]", "expected an object"),
    ({"id": "e"}, "nope", "mapping", "unknown mapping 'nope'"),
    ({"id": "e", "xs": [[1]]}, None, "message.xs[0]", "nested lists have no generic RDF mapping"),
])
def test_messages_that_cannot_be_mapped_name_the_field(message, mapping, where, said):
    with pytest.raises(MappingError) as err:
        Mapper({"entrance": ENTRANCE}).map(message, 0, mapping)
    assert err.value.where == where and said in err.value.message, (err.value.where, err.value.message)


def test_messages_nested_too_deep_are_refused():
    deep: dict = {"id": "x"}
    for _ in range(MAX_DEPTH + 2):
        deep = {"inner": deep}
    with pytest.raises(MappingError, match=f"nested deeper than {MAX_DEPTH} levels"):
        message_to_dict(deep)


@pytest.mark.parametrize("field_type, expected, message", [
    ("sequence<pkg/Customer>", ("pkg/Customer", True), True),
    ("sequence<int32, 5>", ("int32", True), False),
    ("int32[3]", ("int32", True), False),
    ("string<10>", ("string", False), False),
    ("builtin_interfaces/Time", ("builtin_interfaces/Time", False), False),  # a stamp, not a nested node
    ("pkg/msg/Pose", ("pkg/msg/Pose", False), True),
])
def test_rosidl_field_types(field_type, expected, message):
    assert element_type(field_type) == expected
    assert is_message_type(field_type) is message


def test_the_entrance_mapping_matches_its_message_type():
    check_against(ENTRANCE, "printeps_interfaces/msg/Entrance", describe)  # no error


@pytest.mark.parametrize("node, where, said", [
    (NodeMap(fields={"height": "printeps:h"}), "mapping.fields.height", "has no field 'height'"),
    (NodeMap(fields={"customers": "printeps:c"}), "mapping.fields.customers", "is a nested message"),
    (NodeMap(subject="printeps:{name}"), "mapping.subject", "has no field 'name'"),
    (NodeMap(children={"id": ("printeps:x", NodeMap())}), "mapping.children.id", "is not a nested message"),
    (NodeMap(children={"customers": ("printeps:has", NodeMap(timed={"speed": "printeps:s"}))}),
     "mapping.children.customers.timed.speed", "printeps_interfaces/msg/Customer has no field 'speed'"),
])
def test_a_mapping_that_does_not_fit_the_type_names_field_and_type(node, where, said):
    with pytest.raises(MappingError) as err:
        check_against(node, "printeps_interfaces/msg/Entrance", describe)
    assert err.value.where == where and said in err.value.message, (err.value.where, err.value.message)


def test_a_mapping_derived_from_the_type_alone_fits_it_and_maps_a_message():
    spec = introspected_spec("printeps_interfaces/msg/Entrance", describe)
    assert spec["subject"] == "printeps:{id}" and spec["type"] == "printeps:Entrance"
    assert "stamp" not in spec["fields"]  # the stamp is the event time
    assert spec["children"]["customers"]["link"] == "printeps:customers"
    node = node_map_from_spec(spec)
    check_against(node, "printeps_interfaces/msg/Entrance", describe)
    triples = set(Mapper({"e": node}).map({"id": "e1", "customers": [{"id": "c1", "age": 30}]}, 0, "e"))
    assert (p("e1"), p("customers"), p("c1")) in triples
    assert (p("c1"), p("age"), Literal("30", datatype=XSD_INTEGER)) in triples
