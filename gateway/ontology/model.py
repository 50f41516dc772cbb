"""The ontology as an editor sees it: a class tree, the individuals with their typed data values,
and the properties with their ranges.

Why a module of its own: the knowledge editor (class tree, table of individuals, a typed input
per value) needs the *structure* of the Turtle text, while :mod:`gateway.ontology.knowledge`
keeps only the flat ``individual.property`` values the workflows read. The structure is read
with rdflib once per ontology text (cached by the text itself), never on a hot path.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

XSD = "http://www.w3.org/2001/XMLSchema#"
OWL = "http://www.w3.org/2002/07/owl#"
RDF = "http://www.w3.org/1999/02/22-rdf-syntax-ns#"
RDFS = "http://www.w3.org/2000/01/rdf-schema#"


@dataclass
class ClassInfo:
    name: str
    parents: list[str] = field(default_factory=list)
    label: str = ""
    comment: str = ""


@dataclass
class PropertyInfo:
    name: str
    kind: str  # "data" | "object"
    range: str = ""  # xsd local name ("decimal") for data properties, class name for object ones
    domain: str = ""
    comment: str = ""
    unit: str = ""  # printeps:unit annotation ("metres"), for people
    limits: dict[str, str] = field(default_factory=dict)  # facet ("minInclusive") -> lexical, from an OWL 2 datatype restriction


@dataclass
class AssertedValue:
    property: str
    lexical: str
    datatype: str  # xsd local name, e.g. "decimal"


@dataclass
class IndividualInfo:
    name: str
    types: list[str] = field(default_factory=list)
    values: list[AssertedValue] = field(default_factory=list)
    links: list[tuple[str, str]] = field(default_factory=list)  # (object property, individual)


@dataclass
class OntologyModel:
    base: str
    classes: dict[str, ClassInfo]
    properties: dict[str, PropertyInfo]
    individuals: dict[str, IndividualInfo]

    def class_tree(self) -> list[dict[str, Any]]:
        """Classes nested under their first named parent, roots first, alphabetically; each with
        the individuals asserted to be of it."""
        members: dict[str, list[str]] = {}
        for ind in self.individuals.values():
            for t in ind.types:
                members.setdefault(t, []).append(ind.name)
        children: dict[str, list[str]] = {}
        roots = []
        for cls in self.classes.values():
            parent = next((p for p in cls.parents if p in self.classes), None)
            (children.setdefault(parent, []) if parent else roots).append(cls.name)

        def node(name: str) -> dict[str, Any]:
            cls = self.classes[name]
            return {"name": name, "label": cls.label, "comment": cls.comment,
                    "individuals": sorted(members.get(name, [])),
                    "children": [node(c) for c in sorted(children.get(name, []))]}

        return [node(r) for r in sorted(roots)]

    def superclasses(self, name: str) -> list[str]:
        """Every named ancestor of a class (for "inferred from the class hierarchy")."""
        seen: list[str] = []
        todo = list(self.classes.get(name, ClassInfo(name)).parents)
        while todo:
            parent = todo.pop()
            if parent not in seen and parent in self.classes:
                seen.append(parent)
                todo.extend(self.classes[parent].parents)
        return seen


FACETS = ("minInclusive", "maxInclusive", "minExclusive", "maxExclusive")


def _restriction(graph: Any, node: Any) -> tuple[Any, dict[str, str]]:
    """An OWL 2 datatype restriction (``[ owl:onDatatype xsd:decimal ; owl:withRestrictions
    ( [ xsd:minInclusive 0 ] ) ]``): its base datatype and its facets."""
    import rdflib
    from rdflib.collection import Collection

    base_type = next(iter(graph.objects(node, rdflib.OWL.onDatatype)), None)
    limits: dict[str, str] = {}
    for head in graph.objects(node, rdflib.OWL.withRestrictions):
        for facet_node in Collection(graph, head):
            for facet in FACETS:
                value = next(iter(graph.objects(facet_node, rdflib.URIRef(XSD + facet))), None)
                if value is not None:
                    limits[facet] = str(value)
    return base_type, limits


def local(iri: str, base: str) -> str | None:
    """The local name of an IRI in the ontology's namespace (None outside it)."""
    return iri[len(base):] if base and iri.startswith(base) and len(iri) > len(base) else None


def xsd_name(datatype_iri: str) -> str:
    return datatype_iri[len(XSD):] if datatype_iri.startswith(XSD) else (datatype_iri or "string")


@lru_cache(maxsize=4)
def read_model(text: str, base: str, turtle: bool = True) -> OntologyModel:
    """Parse an ontology text (the caller has checked it parses) into an :class:`OntologyModel`."""
    import rdflib

    graph = rdflib.Graph()
    graph.parse(data=text, format="turtle" if turtle else "xml")
    a = rdflib.RDF.type

    def name(node: Any) -> str | None:
        return local(str(node), base) if isinstance(node, rdflib.URIRef) else None

    def text_of(subject: Any, predicate: Any) -> str:
        return next((str(o) for o in graph.objects(subject, predicate)), "")

    classes: dict[str, ClassInfo] = {}
    for s in graph.subjects(a, rdflib.OWL.Class):
        n = name(s)
        if n:
            parents = [p for p in (name(o) for o in graph.objects(s, rdflib.RDFS.subClassOf)) if p]
            classes[n] = ClassInfo(n, parents, text_of(s, rdflib.RDFS.label), text_of(s, rdflib.RDFS.comment))
    properties: dict[str, PropertyInfo] = {}
    for kind, owl_type in (("data", rdflib.OWL.DatatypeProperty), ("object", rdflib.OWL.ObjectProperty)):
        for s in graph.subjects(a, owl_type):
            n = name(s)
            if not n:
                continue
            rng = next(iter(graph.objects(s, rdflib.RDFS.range)), None)
            limits: dict[str, str] = {}
            if kind == "data" and isinstance(rng, rdflib.BNode):
                rng, limits = _restriction(graph, rng)
            rng_name = (xsd_name(str(rng)) if kind == "data" else (name(rng) or "")) if rng is not None else ""
            properties[n] = PropertyInfo(n, kind, rng_name, name(next(iter(graph.objects(s, rdflib.RDFS.domain)), "")) or "",
                                         text_of(s, rdflib.RDFS.comment), text_of(s, rdflib.URIRef(base + "unit")), limits)
    individuals: dict[str, IndividualInfo] = {}
    for s in set(graph.subjects(a, rdflib.OWL.NamedIndividual)) | {
            s for s, o in graph.subject_objects(a) if name(o) in classes}:
        n = name(s)
        if not n or n in classes or n in properties:
            continue
        ind = IndividualInfo(n, sorted(t for t in (name(o) for o in graph.objects(s, a)) if t in classes))
        for p, o in graph.predicate_objects(s):
            pn = name(p)
            if not pn:
                continue
            if isinstance(o, rdflib.Literal):
                ind.values.append(AssertedValue(pn, str(o), xsd_name(str(o.datatype or XSD + "string"))))
            elif name(o):
                ind.links.append((pn, name(o)))  # type: ignore[arg-type]
        ind.values.sort(key=lambda v: v.property)
        ind.links.sort()
        individuals[n] = ind
    return OntologyModel(base, classes, properties, individuals)
