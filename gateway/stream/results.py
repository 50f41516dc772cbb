"""Result events: one per reported window, in plain JSON (the default) and as RDF terms.

Why both: existing clients read ``rows`` as plain JSON values (numbers as numbers, IRIs as
strings); clients that need RDF terms — to tell ``"43"^^xsd:double`` from ``"43.0"^^xsd:decimal``,
or an IRI from a string — ask for the SPARQL 1.1 Query Results JSON format. A
:class:`ResultEvent` is the plain-JSON dict and also carries the RDF terms (attribute ``terms``,
invisible to ``json.dumps``), so one event serves both and :func:`to_sparql_json` converts it
without loss.

SPARQL JSON of an event (the standard members plus the event's own)::

    {"head": {"vars": ["s", "cnt"]},
     "results": {"bindings": [{"s": {"type": "uri", "value": "http://…/c1"},
                               "cnt": {"type": "literal", "value": "3",
                                       "datatype": "http://www.w3.org/2001/XMLSchema#integer"}}]},
     "kind": "result", "query": "…", "window": {"start": 1000, "end": 4000, …}, "path": "fast", …}

ASK gives ``"boolean"`` instead of ``"results"``; CONSTRUCT gives bindings of ``subject``,
``predicate``, ``object`` (one per triple).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from pyoxigraph import BlankNode, Literal, NamedNode

from gateway.rdf.terms import RDF, Term, Triple, local_name, term_to_json, term_to_sparql_json

Row = dict[str, Term]


class ResultEvent(dict):  # type: ignore[type-arg]
    """A ``result`` event: a plain-JSON dict that also keeps the RDF terms of its rows."""

    __slots__ = ("terms", "form")

    def __init__(self, data: dict[str, Any], terms: list[Row], form: str) -> None:
        super().__init__(data)
        self.terms = terms
        self.form = form


def plain_rows(rows: list[Row]) -> list[dict[str, Any]]:
    """Rows as plain JSON values (the default, backwards-compatible form)."""
    return [{k: term_to_json(v) for k, v in row.items()} for row in rows]


def to_sparql_json(event: dict[str, Any]) -> dict[str, Any]:
    """An engine event with its bindings in the SPARQL 1.1 Query Results JSON format.

    ``result`` events get ``head`` and ``results`` (or ``boolean`` for ASK) in place of ``rows``;
    other events (``actions``, ``error``) are returned unchanged."""
    if event.get("kind") != "result":
        return dict(event)
    terms = getattr(event, "terms", None)
    if terms is None:
        raise ValueError("this result event carries no RDF terms (it was not produced by the stream engine)")
    out = {k: v for k, v in event.items() if k != "rows"}
    variables = list(event.get("variables", []))
    if getattr(event, "form", "SELECT") == "ASK":
        value = bool(terms and terms[0].get("ask") is not None and terms[0]["ask"].value == "true")
        return {"head": {}, "boolean": value, **out}
    bindings = [{k: term_to_sparql_json(v) for k, v in row.items()} for row in terms]
    return {"head": {"vars": variables}, "results": {"bindings": bindings}, **out}


def report_to_sparql_json(report: dict[str, Any]) -> dict[str, Any]:
    """A push report whose ``results`` (see ``StreamEngine.push(with_results=True)``) are in the
    SPARQL JSON form."""
    out = dict(report)
    if "results" in out:
        out["results"] = [to_sparql_json(e) for e in out["results"]]
    return out


def term_sort_key(term: Term | None) -> tuple[int, str, str]:
    """A total order on terms, for a deterministic row order (no ORDER BY: any order is right)."""
    if term is None:
        return (0, "", "")
    if isinstance(term, BlankNode):
        return (1, term.value, "")
    if isinstance(term, NamedNode):
        return (2, term.value, "")
    assert isinstance(term, Literal)
    return (3, term.value, term.language or term.datatype.value)


def sort_rows(rows: list[Row], variables: list[str]) -> list[Row]:
    names = list(variables) + sorted({k for row in rows for k in row} - set(variables))
    return sorted(rows, key=lambda row: [term_sort_key(row.get(v)) for v in names])


def row_key(row: Row) -> frozenset[tuple[str, Term]]:
    return frozenset(row.items())


def stream_diff(current: list[Row], previous: list[Row] | None, operator: str) -> list[Row]:
    """The rows an RSP-QL stream operator reports: RSTREAM all of them, ISTREAM those not in the
    previous evaluation, DSTREAM those of the previous evaluation that are gone (set semantics)."""
    if operator == "RSTREAM":
        return current
    before = {row_key(r) for r in previous or []}
    if operator == "ISTREAM":
        return [r for r in current if row_key(r) not in before]
    now = {row_key(r) for r in current}
    out, seen = [], set()
    for r in previous or []:
        key = row_key(r)
        if key not in now and key not in seen:
            seen.add(key)
            out.append(r)
    return out


def rows_to_triples(rows: Iterable[Row]) -> list[Triple]:
    """CONSTRUCT rows (subject, predicate, object) as triples."""
    return [(r["subject"], r["predicate"], r["object"]) for r in rows
            if "subject" in r and "predicate" in r and "object" in r]


def triples_as_facts(rows: list[Row]) -> list[Row]:
    """CONSTRUCT rows grouped by subject: one row per subject, ``subject`` plus one entry per
    predicate (its local name; ``rdf:type`` is ``type``; several values: the first in term order).
    This is what a rule binding on a stream reads."""
    by_subject: dict[Term, Row] = {}
    for r in sorted(rows, key=lambda r: (term_sort_key(r.get("subject")), term_sort_key(r.get("predicate")),
                                         term_sort_key(r.get("object")))):
        s, p, o = r.get("subject"), r.get("predicate"), r.get("object")
        if s is None or p is None or o is None:
            continue
        fact = by_subject.setdefault(s, {"subject": s})
        field = "type" if p.value == RDF + "type" else local_name(p.value)  # type: ignore[union-attr]
        fact.setdefault(field, o)
    return list(by_subject.values())
