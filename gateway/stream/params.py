"""Query parameters bound from the teahouse ontology, re-bound when the ontology file changes.

Why: the published query compares with ``?distance_to_entrance`` which it never binds; the papers
obtain it "using a SPARQL query ... based on the cafe ontology". Editing the ontology (e.g. the
Kinect moved: 3.3 m → 2.8 m) must change detection without a restart, so the file's modification
time and size are checked before each window evaluation (one ``stat``) and the ontology reloaded
when they change. A file that no longer parses keeps the last good ontology and reports the error.
"""

from __future__ import annotations

import logging
import os
import threading
from pathlib import Path
from typing import Iterable

from pyoxigraph import Literal, NamedNode, Quad, QuerySolutions, RdfFormat, Store

from gateway.rdf.terms import Triple
from gateway.stream.query import ParamSpec

log = logging.getLogger(__name__)

_FORMATS = {".ttl": RdfFormat.TURTLE, ".owl": RdfFormat.RDF_XML, ".rdf": RdfFormat.RDF_XML,
            ".xml": RdfFormat.RDF_XML, ".nt": RdfFormat.N_TRIPLES}


class ParamError(ValueError):
    """A parameter that cannot be bound (no ontology, query error, no result)."""


def term_sparql(term: NamedNode | Literal) -> str:
    """A term as SPARQL text, to substitute for a parameter variable."""
    if isinstance(term, NamedNode):
        return f"<{term.value}>"
    if isinstance(term, Literal):
        lexical = term.value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")
        if term.language:
            return f'"{lexical}"@{term.language}'
        return f'"{lexical}"^^<{term.datatype.value}>'
    raise ParamError(f"a parameter cannot be bound to {term!r}")


class OntologySource:
    """The ontology file as a pyoxigraph store, reloaded when the file changes."""

    def __init__(self, path: str | os.PathLike[str] | None) -> None:
        self.path = Path(path) if path else None
        self.version = 0
        self.error: str | None = None
        self._store: Store | None = None
        self._triples: frozenset[Triple] = frozenset()
        self._stamp: tuple[int, int] | None = None
        self._lock = threading.Lock()

    def refresh(self) -> bool:
        """Reload if the file changed; True when a new version was loaded."""
        if self.path is None:
            return False
        try:
            st = self.path.stat()
        except OSError as exc:
            self._fail(f"{self.path}: {exc.strerror or exc}")
            return False
        stamp = (st.st_mtime_ns, st.st_size)
        if stamp == self._stamp:
            return False
        with self._lock:
            if stamp == self._stamp:
                return False
            fmt = _FORMATS.get(self.path.suffix.lower(), RdfFormat.TURTLE)
            store = Store()
            try:
                store.load(path=str(self.path), format=fmt)
            except (SyntaxError, ValueError, OSError) as exc:
                self._stamp = stamp  # do not re-parse a broken file on every window
                self._fail(f"{self.path}: {exc}")
                return False
            self._store = store
            self._triples = frozenset((q.subject, q.predicate, q.object)  # type: ignore[misc]
                                      for q in store.quads_for_pattern(None, None, None))
            self._stamp = stamp
            self.version += 1
            self.error = None
            log.info("ontology %s loaded (version %d, %d triples)", self.path, self.version, len(self._triples))
            return True

    def set_graph(self, triples: Iterable[Triple]) -> None:
        """Serve these triples from now on (the gateway's knowledge base feeds the ontology this
        way, inferred facts included); the file, if any, is no longer watched."""
        store = Store()
        kept = frozenset(triples)
        store.extend(Quad(s, p, o) for s, p, o in kept)  # type: ignore[arg-type]
        with self._lock:
            self.path = None
            self._store, self._triples = store, kept
            self.version += 1
            self.error = None

    def _fail(self, message: str) -> None:
        if message != self.error:
            log.warning("ontology not (re)loaded, keeping the previous one: %s", message)
        self.error = message

    @property
    def triples(self) -> frozenset[Triple]:
        self.refresh()
        return self._triples

    def bind(self, spec: ParamSpec) -> str:
        """The SPARQL text of a parameter's value (constant, or first row/column of its query)."""
        if spec.value is not None:
            return spec.value
        self.refresh()
        if self._store is None:
            raise ParamError(f"?{spec.name}: no ontology loaded ({self.error or 'no ontology file configured'})")
        try:
            result = self._store.query(spec.sparql or "")
        except SyntaxError as exc:
            raise ParamError(f"?{spec.name}: the ontology query is invalid: {exc}") from None
        if not isinstance(result, QuerySolutions):
            raise ParamError(f"?{spec.name}: the ontology query must be a SELECT")
        for solution in result:
            for term in solution:
                if term is not None:
                    return term_sparql(term)  # type: ignore[arg-type]
        raise ParamError(f"?{spec.name}: the ontology query returned no value")
