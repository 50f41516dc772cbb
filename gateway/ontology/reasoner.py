"""OWL + SWRL reasoning with Pellet, kept warm in the gateway's JVM.

Why this way:
- Pellet is needed (HermiT cannot infer data-property values nor run SWRL built-ins, and the
  papers' greeting rule infers ``greeting(?pepper, "Welcome. Two seats?")``).
- owlready2's ``sync_reasoner_pellet`` starts a new Java process per call (2.5–4 s); here Pellet's
  OWL API reasoner (owlready2's own bundled jars, put on the classpath by ``gateway.base.jvm``) runs in
  the already-running JVM: tens of milliseconds per call.
- owlready2 keeps inferred facts forever (``http://inferrences/``); every call therefore builds a
  fresh owlready2 World (ontology + SWRL rules + posted individuals) and a fresh Pellet reasoner,
  so no inferred fact outlives the call that inferred it.

owlready2 is used to read the SWRL text (``ontology/teahouse.swrl``, one rule per line) and to
write the whole world as RDF/XML for the OWL API; rdflib converts the Turtle ontology and posted
Turtle (owlready2 cannot parse Turtle).
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import os
import tempfile
import threading
import time
from dataclasses import dataclass, field
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any, Callable

from gateway.base import jvm

log = logging.getLogger(__name__)

OWL_THING = "http://www.w3.org/2002/07/owl#Thing"
INPUT_IRI = "http://printeps.org/cafe/input"
MAX_INDIVIDUALS = 10_000


#: What Pellet infers from an ontology and its SWRL rules alone, by those texts (a few, newest kept).
#: Why: every knowledge base derives this when it starts and after every change, and the same texts
#: always give the same answer; gateways built one after another in one process (the test suite
#: builds over a hundred, each from the shipped teahouse files) and reloads that change nothing
#: then reuse it instead of paying owlready2 and Pellet again (about half a second each).
#: It is also kept on disk (:func:`_plain_file`), so a process that starts on texts some process
#: of the host has already reasoned over (every restart, every ``--workers`` process, every
#: gateway process a test starts) skips rdflib, owlready2 and Pellet: ~1 CPU-s of a cold start.
_PLAIN_KEEP = 4
_PLAIN_FILES_KEPT = 16
#: Part of the disk key: a new answer format or reasoner version must not read old answers.
_PLAIN_FORMAT = "1"
_plain: "dict[tuple[str, str, str, str], tuple[list[dict[str, Any]], list[dict[str, str]]]]" = {}
_plain_lock = threading.Lock()


def _plain_key(text: "KnowledgeText") -> tuple[str, str, str, str]:
    return (text.ontology, text.swrl, text.ontology_file, text.swrl_file)


def _plain_dir() -> Path:
    """The per-user cache shared by the host's gateway processes (as the compiled rule units')."""
    return Path(os.environ.get("PRINTEPS_CACHE_DIR", Path.home() / ".cache" / "printeps")) / "reasoner"


def _plain_file(text: "KnowledgeText") -> Path:
    """The disk copy of one answer: named by a digest of the texts, their file names, the answer
    format and the owlready2 release (whose bundled Pellet jars do the reasoning)."""
    try:
        from importlib.metadata import version

        release = version("owlready2")
    except Exception:  # metadata missing: a name no other release shares is still safe
        release = "unknown"
    digest = hashlib.sha256()
    for part in (_PLAIN_FORMAT, release, *_plain_key(text)):
        digest.update(part.encode("utf-8"))
        digest.update(b"\0")
    return _plain_dir() / f"{digest.hexdigest()[:32]}.json"


def _plain_known(text: "KnowledgeText") -> dict[str, Any] | None:
    with _plain_lock:
        found = _plain.get(_plain_key(text))
    if found is None:
        found = _plain_read(text)
        if found is None:
            return None
        with _plain_lock:
            _plain_keep(text, found)
    inferred, types = found
    return {"inferred": [dict(t) for t in inferred], "types": [dict(t) for t in types]}


def _plain_read(text: "KnowledgeText") -> tuple[list[dict[str, Any]], list[dict[str, str]]] | None:
    """The disk copy, or None (missing, or unreadable: then it is reasoned again and rewritten)."""
    try:
        data = json.loads(_plain_file(text).read_text(encoding="utf-8"))
        return list(data["inferred"]), list(data["types"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _plain_remember(text: "KnowledgeText", inferred: list[dict[str, Any]], types: list[dict[str, str]]) -> None:
    with _plain_lock:
        _plain_keep(text, (inferred, types))
    _plain_write(text, inferred, types)


def _plain_keep(text: "KnowledgeText", found: tuple[list[dict[str, Any]], list[dict[str, str]]]) -> None:
    """Into the in-process copies (caller holds ``_plain_lock``)."""
    inferred, types = found
    _plain[_plain_key(text)] = ([dict(t) for t in inferred], [dict(t) for t in types])
    while len(_plain) > _PLAIN_KEEP:
        _plain.pop(next(iter(_plain)))


def _plain_write(text: "KnowledgeText", inferred: list[dict[str, Any]], types: list[dict[str, str]]) -> None:
    """Write the disk copy whole (a temporary file renamed over it: readers in other processes
    never see half of one) and keep the newest few. Best effort: a read-only home only loses time."""
    target = _plain_file(text)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile("w", encoding="utf-8", dir=target.parent, suffix=".tmp",
                                         delete=False) as out:
            json.dump({"inferred": inferred, "types": types}, out)
        os.replace(out.name, target)
        kept = sorted(target.parent.glob("*.json"), key=lambda p: p.stat().st_mtime, reverse=True)
        for old in kept[_PLAIN_FILES_KEPT:]:
            old.unlink(missing_ok=True)
    except OSError as exc:
        log.debug("the reasoner's answer was not kept on disk: %s", exc)


class ReasonerError(ValueError):
    """Bad ontology, rules or input; ``where`` names the file:line or the JSON path."""

    def __init__(self, message: str, where: str = "", status: int = 422) -> None:
        super().__init__(f"{where}: {message}" if where else message)
        self.message = message
        self.where = where
        self.status = status

    def to_dict(self) -> dict[str, Any]:
        return {"error": self.message, "where": self.where}


@dataclass(frozen=True)
class KnowledgeText:
    """The texts the reasoner works on: the ontology (Turtle or RDF/XML) and the SWRL rules
    (one per line), with the file names errors should name, and a version that changes with them."""

    version: int
    ontology: str
    swrl: str
    ontology_file: str = "teahouse.ttl"
    swrl_file: str = "teahouse.swrl"


@dataclass
class _OntologyText:
    """The ontology as N-Triples plus its vocabulary, cached per knowledge version."""

    stamp: int
    ntriples: bytes
    base: str
    ontology_iri: str
    classes: set[str]
    object_properties: set[str]
    data_properties: set[str]
    rules: list[tuple[int, str]] = field(default_factory=list)
    swrl_file: str = "teahouse.swrl"


class Reasoner:
    """``reason(data)``: the facts Pellet infers from the ontology, SWRL rules and posted data.

    ``source()`` gives the current :class:`KnowledgeText` (the gateway's knowledge base, which
    follows the catalog); the parsed ontology is cached per text version.
    """

    def __init__(self, source: Callable[[], KnowledgeText]) -> None:
        self.source = source
        self._cache: _OntologyText | None = None
        self._lock = threading.Lock()

    @classmethod
    def from_files(cls, ontology_file: str | Path, swrl_file: str | Path | None) -> "Reasoner":
        """A reasoner over two files, re-read when they change (tools and tests; a gateway feeds
        its reasoner from the knowledge base instead)."""
        paths = [Path(ontology_file), Path(swrl_file) if swrl_file else None]
        seen: dict[str, Any] = {"stamp": None, "text": None}

        def source() -> KnowledgeText:
            try:
                stamp = tuple((p.stat().st_mtime_ns, p.stat().st_size) if p else None for p in paths)
            except OSError as exc:
                raise ReasonerError(f"cannot read: {exc.strerror or exc}", str(exc.filename), 500) from None
            if stamp != seen["stamp"]:
                version = (seen["text"].version + 1) if seen["text"] else 1
                seen["text"] = KnowledgeText(version, _read_text(paths[0]), _read_text(paths[1]) if paths[1] else "",
                                             paths[0].name, paths[1].name if paths[1] else "teahouse.swrl")
                seen["stamp"] = stamp
            return seen["text"]

        return cls(source)

    # -- the ontology --------------------------------------------------------------------------
    def _ontology(self) -> _OntologyText:
        text = self.source()
        if self._cache is not None and self._cache.stamp == text.version:
            return self._cache
        import rdflib
        from rdflib.namespace import OWL, RDF

        graph = rdflib.Graph()
        fmt = "turtle" if text.ontology_file.lower().endswith((".ttl", ".n3")) else "xml"
        try:
            graph.parse(data=text.ontology, format=fmt)
        except Exception as exc:
            raise ReasonerError(f"the ontology does not parse: {exc}", text.ontology_file, 422) from None
        onto_iris = [str(s) for s in graph.subjects(RDF.type, OWL.Ontology)]
        ontology_iri = onto_iris[0] if onto_iris else "http://printeps.org/cafe/entrance"
        classes = {str(s) for s in graph.subjects(RDF.type, OWL.Class)}
        objs = {str(s) for s in graph.subjects(RDF.type, OWL.ObjectProperty)}
        datas = {str(s) for s in graph.subjects(RDF.type, OWL.DatatypeProperty)}
        base = ontology_iri if ontology_iri.endswith(("/", "#")) else ontology_iri + "/"
        rules = _rules(text.swrl)
        self._cache = _OntologyText(text.version, graph.serialize(format="nt", encoding="utf-8"), base, ontology_iri,
                                    classes, objs, datas, rules, text.swrl_file)
        return self._cache

    def warm_up(self) -> None:
        """Start the JVM and load Pellet now (call from the main thread at start-up), so the first
        request does not pay for it. Failures are logged: reasoning then fails per request."""
        try:
            self.reason(None)
        except Exception as exc:  # a broken ontology must not stop the gateway from starting
            log.error("the reasoner could not be warmed up: %s", exc)

    # -- reasoning -----------------------------------------------------------------------------
    def reason(self, data: dict[str, Any] | str | None = None) -> dict[str, Any]:
        """Reason over the ontology plus ``data`` (JSON individuals, or Turtle text).

        Returns ``{"inferred": [{subject, predicate, object}], "types": [{individual, class}],
        "duration_ms"}`` with only facts that were not asserted.
        """
        started = time.perf_counter()
        plain = self.source() if data is None else None
        if plain is not None:
            known = _plain_known(plain)
            if known is not None:
                return {**known, "duration_ms": round((time.perf_counter() - started) * 1000, 2)}
        with self._lock:
            onto = self._ontology()
            input_nt = self._input_ntriples(data, onto)
            world_xml, asserted = self._world(onto, input_nt)
            inferred, types = self._pellet(world_xml, asserted)
        if plain is not None and onto.stamp == plain.version:  # computed from the texts of the key
            _plain_remember(plain, inferred, types)
        return {"inferred": inferred, "types": types, "duration_ms": round((time.perf_counter() - started) * 1000, 2)}

    def _input_ntriples(self, data: dict[str, Any] | str | None, onto: _OntologyText) -> bytes:
        import rdflib

        graph = rdflib.Graph()
        if data is None:
            return b""
        if isinstance(data, str):
            try:
                graph.parse(data=data, format="turtle")
            except Exception as exc:
                raise ReasonerError(f"the Turtle does not parse: {exc}", "body") from None
        else:
            _json_to_graph(data, onto, graph)
        return graph.serialize(format="nt", encoding="utf-8")

    def _world(self, onto: _OntologyText, input_nt: bytes) -> tuple[str, set[tuple[str, str, str]]]:
        """A fresh owlready2 World with ontology, rules and input; returns RDF/XML and asserted facts."""
        import owlready2

        world = owlready2.World()
        try:
            main = world.get_ontology(onto.ontology_iri).load(fileobj=io.BytesIO(onto.ntriples), format="ntriples")
            if input_nt:
                world.get_ontology(INPUT_IRI).load(fileobj=io.BytesIO(input_nt), format="ntriples")
        except Exception as exc:
            raise ReasonerError(f"owlready2 cannot load the data: {exc}", "body") from None
        namespace = main.get_namespace(onto.base)
        asserted = {(str(s), str(p), _norm(o)) for s, p, o in _iter_triples(world)}
        with namespace:
            for line_no, text in onto.rules:
                try:
                    owlready2.Imp(namespace=main).set_as_rule(text, namespaces=[namespace])
                except Exception as exc:
                    raise ReasonerError(f"invalid SWRL rule: {exc}", f"{onto.swrl_file}:{line_no}", 422) from None
        buf = io.BytesIO()
        world.save(buf, format="rdfxml")
        world.close()
        return buf.getvalue().decode("utf-8"), asserted

    def _pellet(self, world_xml: str, asserted: set[tuple[str, str, str]]) -> tuple[list[dict[str, Any]], list[dict[str, str]]]:
        manager = jvm.jclass("org.semanticweb.owlapi.apibinding.OWLManager").createOWLOntologyManager()
        source = jvm.jclass("org.semanticweb.owlapi.io.StringDocumentSource")(world_xml)
        factory = jvm.jclass("com.clarkparsia.pellet.owlapiv3.PelletReasonerFactory").getInstance()
        try:
            ontology = manager.loadOntologyFromOntologyDocument(source)
        except Exception as exc:  # the OWL API refuses what owlready2 wrote (e.g. a literal as an individual)
            raise ReasonerError(f"the OWL API cannot read the rules and data: {_java_message(exc)}", "rules", 422) from None
        reasoner = factory.createReasoner(ontology)
        try:
            if not reasoner.isConsistent():
                raise ReasonerError("the ontology with the posted individuals is inconsistent", "body")
            inferred: list[dict[str, Any]] = []
            types: list[dict[str, str]] = []
            data_props = list(ontology.getDataPropertiesInSignature())
            obj_props = list(ontology.getObjectPropertiesInSignature())
            for ind in ontology.getIndividualsInSignature():
                s = str(ind.getIRI().toString())
                for node in reasoner.getTypes(ind, False):
                    for cls in node.getEntities():
                        c = str(cls.getIRI().toString())
                        if c != OWL_THING and (s, _RDF_TYPE, c) not in asserted:
                            types.append({"individual": s, "class": c})
                for prop in obj_props:
                    p = str(prop.getIRI().toString())
                    for node in reasoner.getObjectPropertyValues(ind, prop).getFlattened():
                        o = str(node.getIRI().toString())
                        if (s, p, o) not in asserted:
                            inferred.append({"subject": s, "predicate": p, "object": o, "object_type": "iri"})
                for prop in data_props:
                    p = str(prop.getIRI().toString())
                    for lit in reasoner.getDataPropertyValues(ind, prop):
                        datatype = str(lit.getDatatype().getIRI().toString())
                        lexical = str(lit.getLiteral())
                        value = _literal_value(lexical, datatype)
                        if (s, p, _norm(value)) not in asserted:
                            inferred.append({"subject": s, "predicate": p, "object": value, "object_type": "literal",
                                             "lexical": lexical, "datatype": datatype})
        except ReasonerError:
            raise
        except Exception as exc:
            raise ReasonerError(f"Pellet failed: {exc}", "pellet", 500) from None
        finally:
            reasoner.dispose()
        key = lambda d: tuple(str(v) for v in d.values())  # noqa: E731 - deterministic order
        return sorted(inferred, key=key), sorted(types, key=key)


_RDF_TYPE = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type"


def _java_message(exc: Exception) -> str:
    """The innermost sentence of a (nested) Java exception's message."""
    return str(exc).rsplit("Exception: ", 1)[-1].strip()


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ReasonerError(f"cannot read: {exc.strerror or exc}", str(path), 500) from None


def _rules(text: str) -> list[tuple[int, str]]:
    """(line number, rule) per SWRL rule line; blank lines and ``#`` comments skipped."""
    return [(i, line.strip()) for i, line in enumerate(text.splitlines(), 1)
            if line.strip() and not line.lstrip().startswith("#")]


def _iter_triples(world: Any) -> Any:
    """All (s, p, o) of a world as Python values (IRIs as strings, literals as values)."""
    yield from world.as_rdflib_graph().triples((None, None, None))


def _norm(value: Any) -> str:
    """A comparable form: numbers by value (2 == 2.0), booleans, strings, IRIs."""
    if hasattr(value, "toPython"):
        value = value.toPython()
    if isinstance(value, bool):
        return "bool:" + str(value).lower()
    if isinstance(value, (int, float, Decimal)):
        try:
            return "num:" + str(Decimal(str(value)).normalize())
        except InvalidOperation:
            return str(value)
    return str(value)


def _literal_value(lexical: str, datatype: str) -> Any:
    tail = datatype.rsplit("#", 1)[-1]
    try:
        if tail in ("integer", "int", "long", "short", "byte", "nonNegativeInteger", "positiveInteger"):
            return int(lexical)
        if tail in ("decimal", "double", "float"):
            number = Decimal(lexical)
            return int(number) if number == number.to_integral_value() and tail == "decimal" and "." not in lexical \
                else float(number)
        if tail == "boolean":
            return lexical in ("true", "1")
    except (ValueError, InvalidOperation):
        return lexical
    return lexical


def _json_to_graph(data: dict[str, Any], onto: _OntologyText, graph: Any) -> None:
    """JSON individuals → RDF: ``{"individuals": [{"id", "types": [...], "properties": {...}}]}``.

    Names are local names in the ontology's namespace (or full IRIs). A property's kind comes from
    the ontology: object-property values name individuals, data-property values are literals.
    """
    import rdflib
    from rdflib.namespace import OWL, RDF, XSD

    if not isinstance(data, dict) or not isinstance(data.get("individuals"), list):
        raise ReasonerError("expected {\"individuals\": [ … ]}", "body")
    individuals = data["individuals"]
    if len(individuals) > MAX_INDIVIDUALS:
        raise ReasonerError(f"at most {MAX_INDIVIDUALS} individuals", "body.individuals")

    def iri(name: Any, where: str) -> rdflib.URIRef:
        if not isinstance(name, str) or not name.strip():
            raise ReasonerError(f"expected a name, got {name!r}", where)
        if "://" in name:
            return rdflib.URIRef(name)
        if not all(ch.isalnum() or ch in "_-." for ch in name):
            raise ReasonerError(f"{name!r} is not a valid local name", where)
        return rdflib.URIRef(onto.base + name)

    for i, ind in enumerate(individuals):
        where = f"individuals[{i}]"
        if not isinstance(ind, dict):
            raise ReasonerError("expected an object", where)
        subject = iri(ind.get("id"), f"{where}.id")
        graph.add((subject, RDF.type, OWL.NamedIndividual))
        types = ind.get("types", [])
        for j, t in enumerate(types if isinstance(types, list) else [types]):
            cls = iri(t, f"{where}.types[{j}]")
            if str(cls) not in onto.classes:
                raise ReasonerError(f"unknown class {t!r}", f"{where}.types[{j}]")
            graph.add((subject, RDF.type, cls))
        props = ind.get("properties", {})
        if not isinstance(props, dict):
            raise ReasonerError("expected an object of property: value(s)", f"{where}.properties")
        for name, raw in props.items():
            here = f"{where}.properties.{name}"
            prop = iri(name, here)
            values = raw if isinstance(raw, list) else [raw]
            for k, value in enumerate(values):
                at = here + (f"[{k}]" if isinstance(raw, list) else "")
                if str(prop) in onto.object_properties:
                    graph.add((subject, prop, iri(value, at)))
                elif str(prop) in onto.data_properties:
                    if isinstance(value, bool):
                        graph.add((subject, prop, rdflib.Literal(value, datatype=XSD.boolean)))
                    elif isinstance(value, int):
                        graph.add((subject, prop, rdflib.Literal(value, datatype=XSD.integer)))
                    elif isinstance(value, float):
                        graph.add((subject, prop, rdflib.Literal(Decimal(repr(value)), datatype=XSD.decimal)))
                    elif isinstance(value, str):
                        graph.add((subject, prop, rdflib.Literal(value)))
                    else:
                        raise ReasonerError(f"a data value must be a number, boolean or string, got {value!r}", at)
                else:
                    raise ReasonerError(f"unknown property {name!r}", here)
