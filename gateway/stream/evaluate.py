"""Evaluating one window: its contents, and the general SPARQL path (pyoxigraph; rdflib for comparison).

Window semantics (C-SPARQL / RSP-QL): the triples of all the query's ``FROM STREAM`` windows plus
its static graphs form the default graph (a set: a triple repeated in the window counts once);
each named window (``FROM NAMED WINDOW <w> ON …``) is the named graph ``<w>`` (``WINDOW <w> { … }``
is ``GRAPH <w> { … }``). ``f:timestamp(?s, ?p, ?o)`` is the timestamp (ms, xsd:integer) of the
latest occurrence of that triple in any of the query's windows; for a triple that is in no stream
window it is unbound (the filter fails).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from pyoxigraph import (
    DefaultGraph,
    Literal,
    NamedNode,
    Quad,
    QueryBoolean,
    QuerySolutions,
    QueryTriples,
    Store,
)

from gateway.rdf.terms import CSPARQL_FN, XSD_INTEGER, Term, Triple, canonical_term

TIMESTAMP_FN = CSPARQL_FN + "timestamp"
Row = dict[str, Term]


@dataclass
class WindowData:
    """What one evaluation sees: stream triples with their latest timestamps, plus static graphs.

    ``stamped``: the default graph's stream triples; ``windows``: the named windows' triples;
    ``static``/``named``: the static default and named graphs; ``segments``: the sealed pieces
    ``stamped`` was merged from (one stream only; lets the fast path cache its encoding);
    ``at_ms``: the evaluation instant when it is not the window's end (content up to it)."""

    start_ms: int
    end_ms: int
    stamped: dict[Triple, int] = field(default_factory=dict)
    static: frozenset[Triple] = frozenset()
    named: dict[str, frozenset[Triple]] = field(default_factory=dict)
    windows: dict[str, dict[Triple, int]] = field(default_factory=dict)
    segments: list[Any] | None = None
    at_ms: int | None = None

    def triples(self) -> set[Triple]:
        return set(self.stamped) | set(self.static)

    @property
    def size(self) -> int:
        """Distinct stream triples the query sees (all its windows)."""
        if not self.windows:
            return len(self.stamped)
        seen = set(self.stamped)
        for content in self.windows.values():
            seen.update(content)
        return len(seen)

    @property
    def empty(self) -> bool:
        return not self.stamped and not any(self.windows.values())

    def timestamp(self, triple: Triple) -> int | None:
        """The latest timestamp of ``triple`` in any window (None: in no stream window)."""
        ts = self.stamped.get(triple)
        for content in self.windows.values():
            other = content.get(triple)
            if other is not None and (ts is None or other > ts):
                ts = other
        return ts


@dataclass
class Evaluation:
    """The outcome of one query on one window: SELECT rows (or CONSTRUCT triples as rows, or ASK)."""

    variables: list[str]
    rows: list[Row]
    path: str  # "fast", "oxigraph", "rdflib"


def _timestamp_function(window: WindowData) -> Callable[[Term, Term, Term], Literal | None]:
    def timestamp(s: Term, p: Term, o: Term) -> Literal | None:
        # the store hands back its own lexical forms; the window keeps canonical ones
        ts = window.timestamp((s, p, canonical_term(o)))
        return None if ts is None else Literal(str(ts), datatype=XSD_INTEGER)

    return timestamp


def evaluate_oxigraph(sparql: str, window: WindowData) -> Evaluation:
    """The general path: a fresh in-memory pyoxigraph store per window (no stale state)."""
    store = Store()
    graph = DefaultGraph()
    store.extend([Quad(s, p, o, graph) for s, p, o in window.triples()])  # type: ignore[arg-type]
    for iri, triples in window.named.items():
        g = NamedNode(iri)
        store.extend([Quad(s, p, o, g) for s, p, o in triples])  # type: ignore[arg-type]
    for iri, stamped in window.windows.items():
        g = NamedNode(iri)
        store.extend([Quad(s, p, o, g) for s, p, o in stamped])  # type: ignore[arg-type]
    result = store.query(sparql, custom_functions={NamedNode(TIMESTAMP_FN): _timestamp_function(window)})
    return Evaluation(*_collect(result), path="oxigraph")


def _collect(result: Any) -> tuple[list[str], list[Row]]:
    if isinstance(result, (bool, QueryBoolean)):
        result = bool(result)
        return ["ask"], [{"ask": Literal("true" if result else "false",
                                         datatype=NamedNode("http://www.w3.org/2001/XMLSchema#boolean"))}]
    if isinstance(result, QuerySolutions):
        names = [v.value for v in result.variables]
        rows = []
        for solution in result:
            row = {}
            for name in names:
                term = solution[name]
                if term is not None:
                    row[name] = term
            rows.append(row)
        return names, rows
    if isinstance(result, QueryTriples):
        return ["subject", "predicate", "object"], [
            {"subject": t.subject, "predicate": t.predicate, "object": t.object} for t in result
        ]
    raise TypeError(f"unexpected query result {type(result).__name__}")


def check_sparql(sparql: str) -> None:
    """Let pyoxigraph parse the query (on an empty store); raises SyntaxError "error at L:C: …"."""
    window = WindowData(0, 0)
    result = Store().query(sparql, custom_functions={NamedNode(TIMESTAMP_FN): _timestamp_function(window)})
    _collect(result)


# -- rdflib, for the benchmark and cross-checks only (far too slow for live windows) -------------


def evaluate_rdflib(sparql: str, window: WindowData) -> Evaluation:
    """The same semantics with rdflib (used by the benchmark as a peer, and by agreement tests)."""
    import rdflib
    from rdflib.plugins.sparql import operators

    def to_rdflib(term: Term) -> Any:
        if isinstance(term, NamedNode):
            return rdflib.URIRef(term.value)
        if isinstance(term, Literal):
            if term.language:
                return rdflib.Literal(term.value, lang=term.language)
            return rdflib.Literal(term.value, datatype=rdflib.URIRef(term.datatype.value))
        return rdflib.BNode(term.value)

    stamped = {(to_rdflib(s), to_rdflib(p), to_rdflib(o)): ts for (s, p, o), ts in window.stamped.items()}
    if window.windows:
        raise NotImplementedError("the rdflib comparison path has no named windows")

    def timestamp(s: Any, p: Any, o: Any) -> Any:
        ts = stamped.get((s, p, o))
        if ts is None:
            from rdflib.plugins.sparql.sparql import SPARQLError
            raise SPARQLError("no timestamp")
        return rdflib.Literal(ts, datatype=rdflib.XSD.integer)

    operators.register_custom_function(rdflib.URIRef(TIMESTAMP_FN), timestamp, override=True)
    graph = rdflib.Graph()
    for s, p, o in window.triples():
        graph.add((to_rdflib(s), to_rdflib(p), to_rdflib(o)))
    result = graph.query(sparql)
    names = [str(v) for v in (result.vars or [])]
    rows: list[Row] = []
    for binding in result.bindings:
        row: Row = {}
        for var, value in binding.items():
            row[str(var)] = _from_rdflib(value)
        rows.append(row)
    return Evaluation(names, rows, path="rdflib")


def _from_rdflib(value: Any) -> Term:
    import rdflib

    if isinstance(value, rdflib.URIRef):
        return NamedNode(str(value))
    if isinstance(value, rdflib.BNode):
        from pyoxigraph import BlankNode
        return BlankNode(str(value))
    if value.language:
        return Literal(str(value), language=value.language)
    datatype = value.datatype or rdflib.XSD.string
    return Literal(str(value), datatype=NamedNode(str(datatype)))
