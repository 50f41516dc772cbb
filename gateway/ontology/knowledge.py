"""The gateway's knowledge: the teahouse ontology and its SWRL rules, one copy per process.

Why one object: the continuous queries bind parameters from the ontology (``?distance_to_entrance``),
workflows read values from it (``pepper1.robotToHumanDistance``), ``POST /api/reason`` runs Pellet
on it, and the owner edits it. They must all see the same version, and every gateway process
must follow an edit made through any other. So the texts live in the catalog (kind
``knowledge``, items ``ontology`` and ``swrl``; the two files of ``streams.knowledge_dir`` only seed an empty
store), and this object is the one reader in the process: on every change it parses the texts
once, runs Pellet once, and hands the asserted **and inferred** facts to everyone — so a value an
SWRL rule infers reaches the queries, bindings and workflows, not only ``/api/reason``.

A replacement is checked first (the Turtle must parse, Pellet must accept ontology + rules
together); a bad one changes nothing and gives the file, line and column. Seeding, loading and
following other processes are the shared life cycle of :mod:`gateway.base.lifecycle`; the
knowledge is never deleted, and a load or reconcile that finds both texts new derives once.
"""

from __future__ import annotations

import hashlib
import logging
import re
from decimal import Decimal
from pathlib import Path
from typing import Any, Callable

from pyoxigraph import Literal, NamedNode, RdfFormat, parse

from gateway.ontology.reasoner import KnowledgeText, Reasoner, ReasonerError
from gateway.rdf.terms import Triple
from gateway.stream.params import OntologySource
from gateway.base.lifecycle import CatalogLifecycle
from gateway.config import SWRL_SUFFIXES, knowledge_files
from gateway.base.versions import Catalog, CatalogConflict, Version, VersionInfo, VersionMissing

log = logging.getLogger(__name__)

KIND = "knowledge"
NAMES = ("ontology", "swrl")
DEFAULT_FILES = {"ontology": "teahouse.ttl", "swrl": "teahouse.swrl"}
XSD = "http://www.w3.org/2001/XMLSchema#"
RDF_TYPE = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type"


def digest(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


class SeedFolderAmbiguous(ValueError):
    """A seed folder holding two files of one item (two ontologies): which one is meant is not guessed."""


class KnowledgeConflict(Exception):
    """The text the edit started from is not the current one any more."""

    def __init__(self, kind: str, current_hash: str, current_version: int) -> None:
        super().__init__(f"{kind}: the text changed meanwhile (now version {current_version})")
        self.kind, self.current_hash, self.current_version = kind, current_hash, current_version


class KnowledgeInvalid(ValueError):
    """A candidate text Pellet or the parser refused: ``errors`` = [{file, line, column, message}]."""

    def __init__(self, kind: str, errors: list[dict[str, Any]]) -> None:
        super().__init__(f"{kind} rejected: {errors[0]['message']}")
        self.kind, self.errors = kind, errors


class KnowledgeBase(CatalogLifecycle):
    """Current ontology + SWRL texts, their versions, and everything derived from them."""

    kind = KIND
    failures = (OSError, UnicodeDecodeError, SeedFolderAmbiguous)

    def __init__(self, catalog: Catalog | None = None, *, infer: bool = True) -> None:
        super().__init__(catalog)
        # each item's file name, as errors name it and export writes it: the served version's
        # (the name of the file it was seeded from), the defaults until one is served
        self.files = dict(DEFAULT_FILES)
        self.infer = infer
        self._text = KnowledgeText(0, "", "", self.files["ontology"], self.files["swrl"])
        self._infos: dict[str, VersionInfo] = {}
        self.reasoner = Reasoner(lambda: self._text)
        self.ontology = OntologySource(None)  # the stream engine's view (parameters, FROM <ontology>)
        self._values: dict[tuple[str, str], Any] = {}
        self.base = ""
        self.inferred: list[dict[str, Any]] = []
        self.inferred_types: list[dict[str, str]] = []
        self.error: str | None = None
        self._listeners: list[Callable[[str], None]] = []

    # ---- reading --------------------------------------------------------------------------------
    @property
    def version(self) -> int:
        """A local counter that moves with every change (the reasoner's and the queries' cache key)."""
        return self._text.version

    def text(self, kind: str) -> str:
        return self._text.ontology if kind == "ontology" else self._text.swrl

    def info(self, kind: str) -> VersionInfo | None:
        return self._infos.get(kind)

    def value(self, name: str) -> Any:
        """``<individual>.<property>`` in the ontology's namespace, asserted or inferred; None if absent."""
        individual, _, prop = name.partition(".")
        if not individual or not prop:
            raise ValueError(f"ontology value {name!r}: expected <individual>.<property>")
        return self._values.get((individual, prop))

    def values(self) -> dict[str, Any]:
        """Every ``individual.property`` value (for pickers in the workbench)."""
        return {f"{i}.{p}": v for (i, p), v in sorted(self._values.items())}

    def reason(self, data: dict[str, Any] | str | None = None) -> dict[str, Any]:
        return self.reasoner.reason(data)

    def add_listener(self, listener: Callable[[str], None]) -> None:
        """``listener(kind)`` after a change of the ontology or the rules is live here."""
        self._listeners.append(listener)

    # ---- changing -------------------------------------------------------------------------------
    def check(self, kind: str, text: str) -> list[dict[str, Any]]:
        """Errors of a candidate text together with the other one as it is now ([] = acceptable)."""
        return self.trial(kind, text)[0]

    def trial(self, kind: str, text: str) -> tuple[list[dict[str, Any]], dict[str, Any] | None]:
        """Pellet on a candidate text with the other one as it is now: (errors, what it infers).
        Nothing changes; the editor shows what a rule would change before it is saved."""
        name = self.files[kind]
        if "\x00" in text:
            return [{"file": name, "line": 0, "column": 0, "message": "binary content is not an ontology or SWRL text"}], None
        candidate = KnowledgeText(-1, text if kind == "ontology" else self._text.ontology,
                                  text if kind == "swrl" else self._text.swrl, self.files["ontology"], self.files["swrl"])
        try:
            return [], Reasoner(lambda: candidate).reason(None)
        except ReasonerError as exc:
            error = _position(exc, name)
            if "inconsistent" in error["message"]:
                error["message"] = ("Pellet finds the ontology and the rules inconsistent together (a value or a "
                                    "conclusion contradicts the ontology, e.g. a value outside a property's range)")
            return [error], None

    def replace(self, kind: str, text: str, *, author: str, comment: str = "", base_hash: str | None = None,
                base_version: int | None = None) -> VersionInfo:
        """Check, then store and serve a new text of ``kind`` ("ontology" or "swrl")."""
        _kind(kind)
        with self._lock:
            current = self.text(kind)
            served = self.info(kind)
            if base_hash is not None and base_hash != digest(current):
                raise KnowledgeConflict(kind, digest(current), served.version if served else 0)
            errors = self.check(kind, text)
            if errors:
                raise KnowledgeInvalid(kind, errors)
            try:
                info, seq = self.catalog.save(KIND, kind, {"text": text, "file": self.files[kind]}, author=author,
                                              comment=comment, hash=digest(text), base_version=base_version)
            except CatalogConflict as conflict:
                raise KnowledgeConflict(kind, digest(current), conflict.current) from None
            self._serve({kind: (info, seq, text, self.files[kind])})
            return info

    def rollback(self, kind: str, version: int, *, author: str, comment: str = "") -> VersionInfo:
        _kind(kind)
        with self._lock:
            stored = self.catalog.load(KIND, kind, int(version))
            errors = self.check(kind, stored.payload["text"])
            if errors:
                raise KnowledgeInvalid(kind, errors)
            info, seq = self.catalog.set_current(KIND, kind, int(version), author=author,
                                                 comment=comment or f"rollback to version {version}")
            self._serve({kind: (info, seq, stored.payload["text"], stored.payload.get("file"))})
            return info

    def versions(self, kind: str) -> list[VersionInfo]:
        return self.catalog.versions(KIND, _kind(kind))

    def version_text(self, kind: str, version: int) -> tuple[VersionInfo, str]:
        stored = self.catalog.load(KIND, _kind(kind), int(version))
        return stored.info, stored.payload["text"]

    def history(self, kind: str) -> list[dict[str, Any]]:
        return [c.to_dict() for c in self.catalog.history(KIND, _kind(kind))]

    # ---- the shared life cycle's hooks -------------------------------------------------------
    def _seed_paths(self, folder: Path) -> list[Path]:
        """The ontology file (``*.ttl``, ``*.n3``, ``*.owl``, ``*.rdf``) and the SWRL file
        (``*.swrl``) of the folder (``streams.knowledge_dir``), whatever their names."""
        files = knowledge_files(folder)  # one listing of the folder for both items
        return [path for kind in NAMES for path in files[kind]]

    def _read_seed(self, path: Path) -> tuple[str, Path]:
        kind = "swrl" if path.suffix.lower() in SWRL_SUFFIXES else "ontology"
        others = [p.name for p in knowledge_files(path.parent)[kind] if p != path]
        if others:
            raise SeedFolderAmbiguous(f"the folder {path.parent} holds more than one {kind} file ({path.name}, "
                                      f"{', '.join(others)}): keep one")
        return kind, path

    def _store_seed(self, name: str, item: Path, path: Path) -> int:
        """Stored as the repository holds it (not checked: the seed is the reference)."""
        text = path.read_text(encoding="utf-8")
        return self._save_seed(name, {"text": text, "file": path.name}, digest(text), path)

    def _apply(self, name: str, stored: Version, seq: int, *, elsewhere: bool) -> None:
        self._apply_all([(stored, seq)], elsewhere=elsewhere)

    def _apply_all(self, stale: list[tuple[Version, int]], *, elsewhere: bool) -> dict[str, str]:
        """Both texts at once when both are new: Pellet runs once."""
        with self._lock:
            self._serve({_kind(s.info.name): (s.info, seq, s.payload["text"], s.payload.get("file"))
                         for s, seq in stale})
        return {s.info.name: f"serving v{s.info.version}" for s, _ in stale}

    def _withdraw(self, name: str, seq: int) -> None:
        """The knowledge cannot be deleted: keep serving what we have."""

    # ---- deriving ------------------------------------------------------------------------------
    def _serve(self, changes: dict[str, tuple[VersionInfo, int, str, str | None]]) -> None:
        """Make new texts (and their file names) current unless a newer change is served;
        re-derive facts and values."""
        applied = []
        texts = {"ontology": self._text.ontology, "swrl": self._text.swrl}
        for kind, (info, seq, text, file) in changes.items():
            if not self._served.set(kind, info.version, seq):
                continue
            self._infos[kind] = info
            self.files[kind] = file or self.files[kind]
            texts[kind] = text
            applied.append(kind)
        if not applied:
            return
        self._text = KnowledgeText(self._text.version + 1, texts["ontology"], texts["swrl"],
                                   self.files["ontology"], self.files["swrl"])
        self._derive()
        for kind in applied:
            log.info("knowledge: %s now version %d", kind, self._infos[kind].version)
            for listener in list(self._listeners):
                try:
                    listener(kind)
                except Exception:  # a listener must not stop the knowledge from changing
                    log.exception("knowledge listener failed")

    def _derive(self) -> None:
        """Parse the ontology once, add what Pellet infers, and publish both to every reader."""
        triples: set[Triple] = set()
        try:
            fmt = RdfFormat.TURTLE if self.files["ontology"].endswith((".ttl", ".n3")) else RdfFormat.RDF_XML
            for quad in parse(self._text.ontology.encode("utf-8"), format=fmt):
                triples.add((quad.subject, quad.predicate, quad.object))  # type: ignore[arg-type]
        except (SyntaxError, ValueError) as exc:
            self.error = f"{self.files['ontology']}: {exc}"
            log.error("knowledge: the ontology does not parse: %s", exc)
            return
        self.error = None
        self.inferred, self.inferred_types = [], []
        if self.infer and self._text.ontology:
            try:
                reasoned = self.reasoner.reason(None)
                self.inferred, self.inferred_types = reasoned["inferred"], reasoned["types"]
            except ReasonerError as exc:
                self.error = str(exc)
                log.error("knowledge: Pellet could not infer from the current knowledge: %s", exc)
        for fact in self.inferred:
            term = _object_term(fact)
            if term is not None:
                triples.add((NamedNode(fact["subject"]), NamedNode(fact["predicate"]), term))
        self.base = _namespace(self._text.ontology, triples)
        self.ontology.set_graph(triples)
        self._values = _values(triples, self.base)


def _kind(kind: str) -> str:
    if kind not in NAMES:
        raise ValueError(f"unknown knowledge item {kind!r}: use 'ontology' or 'swrl'")
    return kind


def _object_term(fact: dict[str, Any]) -> NamedNode | Literal | None:
    if fact.get("object_type") == "iri":
        return NamedNode(str(fact["object"]))
    if "lexical" in fact and fact.get("datatype"):
        return Literal(str(fact["lexical"]), datatype=NamedNode(fact["datatype"]))
    return None


def _namespace(text: str, triples: set[Triple]) -> str:
    """The namespace of the ontology's terms: the ``printeps`` prefix, else the ontology IRI + '/'."""
    match = re.search(r"@prefix\s+printeps:\s*<([^>]+)>", text)
    if match:
        return match.group(1)
    for s, p, o in triples:
        if p.value == RDF_TYPE and getattr(o, "value", "") == "http://www.w3.org/2002/07/owl#Ontology":
            iri = s.value
            return iri if iri.endswith(("/", "#")) else iri + "/"
    return ""


def _values(triples: set[Triple], base: str) -> dict[tuple[str, str], Any]:
    """(individual, property) -> Python value, for literal-valued facts in the namespace."""
    out: dict[tuple[str, str], Any] = {}
    for s, p, o in triples:
        if not isinstance(o, Literal) or not isinstance(s, NamedNode) or not s.value.startswith(base) \
                or not p.value.startswith(base):
            continue
        out[(s.value[len(base):], p.value[len(base):])] = _python(o)
    return out


def _python(literal: Literal) -> Any:
    datatype = literal.datatype.value if literal.datatype else ""
    lexical = literal.value
    try:
        if datatype in (XSD + "integer", XSD + "int", XSD + "long", XSD + "short", XSD + "nonNegativeInteger"):
            return int(lexical)
        if datatype in (XSD + "decimal", XSD + "double", XSD + "float"):
            return float(Decimal(lexical))
        if datatype == XSD + "boolean":
            return lexical in ("true", "1")
    except (ValueError, ArithmeticError):
        return lexical
    return lexical


def _position(exc: ReasonerError, name: str) -> dict[str, Any]:
    """file/line/column from a ReasonerError (``where`` = "file:line"; rdflib says "at line N")."""
    where = str(exc.where or "")
    message = str(exc.message)
    line = column = 0
    match = re.search(r":(\d+)$", where)
    if match:
        line = int(match.group(1))
    else:
        match = re.search(r"line (\d+)(?:[^\d]+(?:col(?:umn)?|char) (\d+))?", message)
        if match:
            line = int(match.group(1))
            column = int(match.group(2) or 0)
    return {"file": name, "line": line, "column": column, "message": message}


__all__ = ["KnowledgeBase", "KnowledgeConflict", "KnowledgeInvalid", "VersionMissing", "digest"]
