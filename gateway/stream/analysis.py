"""What a query can possibly look at, read from its SPARQL algebra (rdflib's translation).

Why: a window only needs the triples a query can match. When every triple pattern of a query has
a constant predicate (no ``?s ?p ?o``, no negated property path, not DESCRIBE), a triple whose
predicate the query never names cannot change any answer, so the engine drops it when it arrives
(less memory, smaller windows, smaller stores on the general path). The same algebra gives the
fields a CONSTRUCT stream offers to a rule binding.
"""

from __future__ import annotations

import functools
from typing import Any

from pyoxigraph import NamedNode

from gateway.rdf.terms import RDF, local_name
from gateway.stream.evaluate import TIMESTAMP_FN


class _AnyPredicate(Exception):
    """The query can match any predicate."""


def _algebra(sparql: str) -> Any | None:
    try:
        from rdflib.plugins.sparql import prepareQuery

        return prepareQuery(sparql).algebra
    except Exception:  # rdflib cannot read it: no analysis, nothing is dropped
        return None


def relevant_predicates(sparql: str) -> frozenset[NamedNode] | None:
    """The predicates the query can match (None: any — nothing may be dropped)."""
    return _analysed(sparql)[0]


@functools.lru_cache(maxsize=256)
def _analysed(sparql: str) -> tuple[frozenset[NamedNode] | None, tuple[str, ...]]:
    """``(relevant predicates, CONSTRUCT fields)`` of one query text, from one parse.

    Why kept: rdflib's SPARQL parser (pyparsing) takes ~0.1 s a query, and the same texts are read
    again and again: a query is registered twice when it is seeded or changed (the check on a
    scratch engine, then the real one), by every gateway a process builds, and by every replay and
    trial of the workbench. Both answers are immutable and depend on the text alone."""
    algebra = _algebra(sparql)
    return _predicates(algebra), _fields(algebra)


def _predicates(algebra: Any | None) -> frozenset[NamedNode] | None:
    if algebra is None or algebra.name == "DescribeQuery":
        return None
    found: set[str] = set()
    try:
        _walk(algebra, found, set())
    except _AnyPredicate:
        return None
    return frozenset(NamedNode(p) for p in found)


def _walk(node: Any, found: set[str], seen: set[int]) -> None:
    from rdflib.paths import NegatedPath, Path
    from rdflib.term import URIRef

    if id(node) in seen:
        return
    seen.add(id(node))
    name = getattr(node, "name", None)
    if name == "Function" and str(getattr(node, "iri", "")) == TIMESTAMP_FN:
        args = list(node.expr or [])
        if len(args) == 3:
            if isinstance(args[1], URIRef):
                found.add(str(args[1]))
            else:
                raise _AnyPredicate()
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "triples" and isinstance(value, (list, tuple)):
                for triple in value:
                    if isinstance(triple, (list, tuple)) and len(triple) == 3:
                        _predicate(triple[1], found)
            elif key == "template":
                continue  # CONSTRUCT template: produced, not matched
            _walk(value, found, seen)
    elif isinstance(node, (list, tuple)):
        for value in node:
            _walk(value, found, seen)
    elif isinstance(node, NegatedPath):
        raise _AnyPredicate()
    elif isinstance(node, Path):
        _path(node, found)


def _predicate(p: Any, found: set[str]) -> None:
    from rdflib.paths import Path
    from rdflib.term import URIRef

    if isinstance(p, URIRef):
        found.add(str(p))
    elif isinstance(p, Path):
        _path(p, found)
    else:  # a variable predicate
        raise _AnyPredicate()


def _path(path: Any, found: set[str]) -> None:
    from rdflib.paths import (
        AlternativePath,
        InvPath,
        MulPath,
        NegatedPath,
        SequencePath,
    )
    from rdflib.term import URIRef

    if isinstance(path, URIRef):
        found.add(str(path))
    elif isinstance(path, NegatedPath):
        raise _AnyPredicate()
    elif isinstance(path, (SequencePath, AlternativePath)):
        for part in path.args:
            _path(part, found)
    elif isinstance(path, MulPath) and path.mod != "+":
        raise _AnyPredicate()  # p* and p? match every node of the graph with itself
    elif isinstance(path, MulPath):
        _path(path.path, found)
    elif isinstance(path, InvPath):
        _path(path.arg, found)
    else:
        raise _AnyPredicate()


def construct_fields(sparql: str) -> list[str]:
    """What a rule binding can read from a CONSTRUCT query's output: ``subject`` plus the local
    name of every constant predicate in the template (``rdf:type`` is ``type``)."""
    return list(_analysed(sparql)[1])


def _fields(algebra: Any | None) -> tuple[str, ...]:
    fields = ["subject"]
    if algebra is None or algebra.name != "ConstructQuery":
        return tuple(fields)
    from rdflib.term import URIRef

    for triple in algebra.template or []:
        p = triple[1]
        if isinstance(p, URIRef):
            field = "type" if str(p) == RDF + "type" else local_name(str(p))
            if field not in fields:
                fields.append(field)
    return tuple(fields)
