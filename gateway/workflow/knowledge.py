"""Ontology values for ``ontology_value`` modules: ``pepper1.robotToHumanDistance`` -> 1.0.

Why: owners change values such as the distance a robot keeps from people (Table 2 #12-#14) in the
teahouse ontology, not in workflows; a workflow step reads the value when it runs. The Turtle file
is re-read when it changes (size or modification time), so an edit is live for the next run.
Names are ``<individual>.<property>`` in the ontology's own namespace.
"""

from __future__ import annotations

import threading
from decimal import Decimal
from pathlib import Path
from typing import Any

import rdflib
from rdflib.namespace import OWL, RDF


class OntologyValues:
    """Reads datatype property values of named individuals from one ontology file."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._stamp: tuple[int, int] | None = None
        self._graph: rdflib.Graph | None = None
        self._base = ""
        self._lock = threading.Lock()

    def _current(self) -> tuple[rdflib.Graph, str]:
        st = self.path.stat()
        stamp = (st.st_mtime_ns, st.st_size)
        with self._lock:
            if self._graph is None or stamp != self._stamp:
                graph = rdflib.Graph()
                graph.parse(str(self.path), format="turtle" if self.path.suffix in (".ttl", ".n3") else "xml")
                self._graph, self._stamp = graph, stamp
                self._base = _namespace(graph)
            return self._graph, self._base

    def value(self, name: str) -> Any:
        """The value of ``individual.property`` (a number, string or bool), or None when absent."""
        individual, _, prop = name.partition(".")
        if not individual or not prop:
            raise ValueError(f"ontology value {name!r}: expected <individual>.<property>")
        graph, base = self._current()
        found = graph.value(rdflib.URIRef(base + individual), rdflib.URIRef(base + prop))
        if found is None:
            return None
        python = found.toPython() if isinstance(found, rdflib.Literal) else str(found)
        return float(python) if isinstance(python, Decimal) else python


def _namespace(graph: rdflib.Graph) -> str:
    """The namespace of the ontology's terms: the ``printeps`` prefix, else the ontology IRI + '/'."""
    for prefix, namespace in graph.namespaces():
        if prefix == "printeps":
            return str(namespace)
    for iri in graph.subjects(RDF.type, OWL.Ontology):
        text = str(iri)
        return text if text.endswith(("/", "#")) else text + "/"
    return ""
