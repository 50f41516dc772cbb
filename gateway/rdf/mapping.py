"""Messages (ROS message objects or JSON dicts) → RDF triples, driven by declarative mappings.

Why declarative: the papers' knowledge modules "convert data with ROS message format into RDF";
which class and which properties a message field becomes is knowledge about the teahouse ontology,
not code. A :class:`NodeMap` says how one message (or nested message) becomes one RDF node:

- ``subject``: an IRI template filled from the message's fields (``printeps:{id}``), or None for a
  blank node;
- ``rdf_type``: the ontology class of the node;
- ``fields``: scalar field → predicate;
- ``timed``: scalar fields whose values change over time (e.g. a distance). They go on a node per
  reading: ``<subject> <timed_link> <subject>_t<timestamp>`` and ``<subject>_t<ts> <pred> value``,
  which is the shape of the papers' ``printeps:positionAtTime ?ts . ?ts printeps:distance ?d``;
- ``children``: list/nested message fields → (linking predicate, NodeMap of the element).

Messages without a mapping get the generic default: one node per (nested) message, every field
``printeps:<field>``, ``id`` fields naming the node.

Mappings are data: :func:`node_map_from_spec` reads the YAML/JSON form kept in the catalog and in
``ontology/mappings/*.yaml`` (``subject``, ``type``, ``fields``, ``timed``, ``timed_link``,
``children: {field: {link, ...a nested spec}}``), :func:`spec_of` writes it back, and
:func:`check_against` compares a mapping with a message type's fields (rosidl names and types,
nested messages and arrays) so a mapping that names a field the type lacks is refused by name.
:func:`introspected_spec` derives a mapping from a message type alone.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

import yaml

from pyoxigraph import BlankNode, NamedNode

from gateway.rdf.terms import (
    DEFAULT_PREFIXES,
    PRINTEPS,
    RDF_TYPE,
    Term,
    TermError,
    Triple,
    parse_node,
    value_to_term,
)

MAX_DEPTH = 16
MAX_TRIPLES_PER_MESSAGE = 100_000


@dataclass(frozen=True)
class NodeMap:
    """How one (nested) message becomes one RDF node; see the module docstring."""

    subject: str | None = None
    rdf_type: str | None = None
    fields: Mapping[str, str] = field(default_factory=dict)
    timed_link: str = "printeps:positionAtTime"
    timed: Mapping[str, str] = field(default_factory=dict)
    children: Mapping[str, tuple[str, "NodeMap"]] = field(default_factory=dict)


SPEC_KEYS = {"subject", "type", "fields", "timed", "timed_link", "children", "message_type", "description",
             "link", "mapping"}


class MappingError(ValueError):
    """A message that cannot be mapped; ``where`` is the field path (``message.customers[2].id``)."""

    def __init__(self, where: str, message: str) -> None:
        super().__init__(f"{where}: {message}")
        self.where = where
        self.message = message


def message_to_dict(message: Any) -> dict[str, Any]:
    """A ROS message object (rclpy generated class) or a dict as plain JSON-like data."""
    return _plain(message, "message", 0)


def _plain(value: Any, where: str, depth: int) -> Any:
    if depth > MAX_DEPTH:
        raise MappingError(where, f"nested deeper than {MAX_DEPTH} levels")
    if isinstance(value, Mapping):
        return {str(k): _plain(v, f"{where}.{k}", depth + 1) for k, v in value.items()}
    if hasattr(value, "get_fields_and_field_types"):  # a ROS 2 message
        return {name: _plain(getattr(value, name), f"{where}.{name}", depth + 1)
                for name in value.get_fields_and_field_types()}
    if isinstance(value, (list, tuple)) or type(value).__name__ in ("ndarray", "array"):
        return [_plain(v, f"{where}[{i}]", depth + 1) for i, v in enumerate(value)]
    if hasattr(value, "item") and callable(value.item):  # numpy scalar
        return value.item()
    return value


class Mapper:
    """Maps messages to triples with named mappings.

    There are no built-in mappings: the teahouse's (``ontology/mappings/*.yaml``) are data, seeded
    into the Information State and served from it, so a deleted mapping stays deleted."""

    def __init__(self, mappings: Mapping[str, NodeMap] | None = None,
                 prefixes: Mapping[str, str] | None = None) -> None:
        self.mappings: dict[str, NodeMap] = dict(mappings or {})
        self.prefixes = dict(DEFAULT_PREFIXES)
        self.prefixes.update(prefixes or {})
        self._iri_cache: dict[str, NamedNode] = {}

    def map(self, message: Any, timestamp_ms: int, mapping: str | None = None) -> list[Triple]:
        """The triples of one message received at ``timestamp_ms``; generic if no mapping named."""
        data = message_to_dict(message)
        if not isinstance(data, dict):
            raise MappingError("message", f"expected an object, got {type(data).__name__}")
        out: list[Triple] = []
        if mapping is None:
            self._generic(data, "message", int(timestamp_ms), out, 0)
        else:
            if mapping not in self.mappings:
                raise MappingError("mapping", f"unknown mapping {mapping!r}; known: {sorted(self.mappings)}")
            self._node(data, self.mappings[mapping], "message", int(timestamp_ms), out)
        return out

    # -- declared mappings -------------------------------------------------------------------
    def _node(self, data: Any, spec: NodeMap, where: str, ts: int, out: list[Triple]) -> Term:
        if not isinstance(data, dict):
            raise MappingError(where, f"expected an object, got {type(data).__name__}")
        subject = self._subject(spec.subject, data, where)
        if spec.rdf_type:
            out.append((subject, RDF_TYPE, self._iri(spec.rdf_type, where)))
        for name, pred in spec.fields.items():
            if data.get(name) is not None:
                self._values(subject, self._iri(pred, where), data[name], f"{where}.{name}", out)
        timed = [(n, p) for n, p in spec.timed.items() if data.get(n) is not None]
        if timed:
            reading = self._reading_node(subject, ts)
            out.append((subject, self._iri(spec.timed_link, where), reading))
            for name, pred in timed:
                self._values(reading, self._iri(pred, where), data[name], f"{where}.{name}", out)
        for name, (link, child_spec) in spec.children.items():
            children = data.get(name)
            if children is None:
                continue
            items = children if isinstance(children, list) else [children]
            for i, child in enumerate(items):
                child_node = self._node(child, child_spec, f"{where}.{name}[{i}]", ts, out)
                out.append((subject, self._iri(link, where), child_node))
        self._check_size(out, where)
        return subject

    def _subject(self, template: str | None, data: dict[str, Any], where: str) -> NamedNode | BlankNode:
        if template is None:
            return BlankNode()
        names = re.findall(r"{(\w+)}", template)
        missing = [n for n in names if data.get(n) in (None, "")]
        if missing:
            raise MappingError(f"{where}.{missing[0]}", "missing (needed to name the node)")
        filled = template
        for n in names:
            filled = filled.replace("{" + n + "}", _iri_safe(str(data[n])))
        return self._iri(filled, where)

    @staticmethod
    def _reading_node(subject: Term, ts: int) -> Term:
        if isinstance(subject, NamedNode):
            return NamedNode(f"{subject.value}_t{ts}")
        return BlankNode()

    def _values(self, subject: Term, pred: NamedNode, value: Any, where: str, out: list[Triple]) -> None:
        values = value if isinstance(value, list) else [value]
        for i, v in enumerate(values):
            here = where if not isinstance(value, list) else f"{where}[{i}]"
            if isinstance(v, (dict, list)):
                raise MappingError(here, "expected a scalar value")
            try:
                out.append((subject, pred, value_to_term(v, here)))
            except TermError as exc:
                raise MappingError(exc.where, exc.message) from None

    def _iri(self, text: str, where: str) -> NamedNode:
        cached = self._iri_cache.get(text)
        if cached is not None:
            return cached
        node = self._parse_iri(text, where)
        if len(self._iri_cache) < 10_000:
            self._iri_cache[text] = node
        return node

    def _parse_iri(self, text: str, where: str) -> NamedNode:
        try:
            node = parse_node(text, where, self.prefixes)
        except TermError as exc:
            raise MappingError(exc.where, exc.message) from None
        if not isinstance(node, NamedNode):
            raise MappingError(where, f"{text!r} must be an IRI")
        return node

    # -- generic default -----------------------------------------------------------------------
    def _generic(self, data: dict[str, Any], where: str, ts: int, out: list[Triple], depth: int) -> Term:
        if data.get("id") not in (None, ""):
            subject: Term = NamedNode(PRINTEPS + _iri_safe(str(data["id"])))
        else:
            subject = BlankNode()
        for name, value in data.items():
            pred = NamedNode(PRINTEPS + _iri_safe(name))
            items = value if isinstance(value, list) else [value]
            for i, item in enumerate(items):
                here = f"{where}.{name}" + (f"[{i}]" if isinstance(value, list) else "")
                if item is None:
                    continue
                if isinstance(item, dict):
                    out.append((subject, pred, self._generic(item, here, ts, out, depth + 1)))
                elif isinstance(item, list):
                    raise MappingError(here, "nested lists have no generic RDF mapping")
                else:
                    try:
                        out.append((subject, pred, value_to_term(item, here)))
                    except TermError as exc:
                        raise MappingError(exc.where, exc.message) from None
        self._check_size(out, where)
        return subject

    @staticmethod
    def _check_size(out: list[Triple], where: str) -> None:
        if len(out) > MAX_TRIPLES_PER_MESSAGE:
            raise MappingError(where, f"the message maps to more than {MAX_TRIPLES_PER_MESSAGE} triples")


def _iri_safe(text: str) -> str:
    """Characters allowed in an IRI path segment; others percent-encoded."""
    return re.sub(r"[^A-Za-z0-9._~-]", lambda m: "".join(f"%{b:02X}" for b in m.group().encode()), text)


# --------------------------------------------------------------------------- mappings as data


def mappings_from_folder(folder: str | Path) -> dict[str, NodeMap]:
    """The mappings of a folder of ``<name>.yaml`` specs (as ``ontology/mappings``), by name, for
    tools that map messages without a gateway (benchmarks, tests); a gateway serves them from the
    Information State instead. A spec may name one read before it (``mapping: customer``)."""
    mappings: dict[str, NodeMap] = {}
    for path in sorted(Path(folder).glob("*.yaml")):
        spec = yaml.safe_load(path.read_text(encoding="utf-8"))
        mappings[path.stem] = node_map_from_spec(spec, path.name, resolve=mappings)
    return mappings


def node_map_from_spec(spec: Any, where: str = "mapping", resolve: Mapping[str, NodeMap] | None = None,
                       prefixes: Mapping[str, str] | None = None) -> NodeMap:
    """A NodeMap from its data form; MappingError names the bad key (``mapping.children.customers.link``).

    ``children.<field>.mapping: <name>`` reuses another mapping (looked up in ``resolve``).
    """
    if not isinstance(spec, Mapping):
        raise MappingError(where, "a mapping must be an object")
    unknown = sorted(set(spec) - SPEC_KEYS)
    if unknown:
        raise MappingError(f"{where}.{unknown[0]}", f"unknown key; use {', '.join(sorted(SPEC_KEYS - {'link'}))}")
    if "mapping" in spec:
        name = spec["mapping"]
        if not isinstance(name, str) or resolve is None or name not in resolve:
            raise MappingError(f"{where}.mapping", f"no mapping named {name!r}")
        return resolve[name]
    check = Mapper(prefixes=prefixes)
    subject = spec.get("subject")
    if subject is not None and not isinstance(subject, str):
        raise MappingError(f"{where}.subject", "must be an IRI template such as 'printeps:{id}', or null")
    rdf_type = spec.get("type")
    if rdf_type is not None:
        check._iri(_text(rdf_type, f"{where}.type"), f"{where}.type")
    fields = _predicates(spec.get("fields"), f"{where}.fields", check)
    timed = _predicates(spec.get("timed"), f"{where}.timed", check)
    timed_link = _text(spec.get("timed_link", "printeps:positionAtTime"), f"{where}.timed_link")
    check._iri(timed_link, f"{where}.timed_link")
    children_spec = spec.get("children") or {}
    if not isinstance(children_spec, Mapping):
        raise MappingError(f"{where}.children", "must map message fields to {link, ...nested mapping}")
    children: dict[str, tuple[str, NodeMap]] = {}
    for name, child in children_spec.items():
        here = f"{where}.children.{name}"
        if not isinstance(child, Mapping) or not isinstance(child.get("link"), str):
            raise MappingError(here, "needs 'link': the predicate from this node to the nested one")
        check._iri(child["link"], f"{here}.link")
        nested = {k: v for k, v in child.items() if k != "link"}
        children[str(name)] = (child["link"], node_map_from_spec(nested, here, resolve, prefixes))
    return NodeMap(subject=subject, rdf_type=rdf_type, fields=fields, timed_link=timed_link, timed=timed,
                   children=children)


def spec_of(node: NodeMap) -> dict[str, Any]:
    """The data form of a NodeMap (what :func:`node_map_from_spec` reads)."""
    out: dict[str, Any] = {"subject": node.subject}
    if node.rdf_type:
        out["type"] = node.rdf_type
    if node.fields:
        out["fields"] = dict(node.fields)
    if node.timed:
        out["timed"] = dict(node.timed)
        out["timed_link"] = node.timed_link
    if node.children:
        out["children"] = {name: {"link": link, **spec_of(child)} for name, (link, child) in node.children.items()}
    return out


def _text(value: Any, where: str) -> str:
    if not isinstance(value, str) or not value:
        raise MappingError(where, "must be a non-empty text (an IRI or prefixed name)")
    return value


def _predicates(value: Any, where: str, check: "Mapper") -> dict[str, str]:
    if value is None:
        return {}
    if not isinstance(value, Mapping):
        raise MappingError(where, "must map message fields to predicates")
    out = {}
    for name, pred in value.items():
        check._iri(_text(pred, f"{where}.{name}"), f"{where}.{name}")
        out[str(name)] = pred
    return out


# Message types as rosidl describes them: ``{"id": "string", "customers": "sequence<pkg/Customer>",
# "stamp": "builtin_interfaces/Time"}``; ``describe`` (injected) gives the fields of a nested type.
FieldTypes = Mapping[str, str]
Describe = Callable[[str], FieldTypes]
_SEQUENCE = re.compile(r"^(?:sequence<([^,>]+)(?:,\s*\d+)?>|([^\[]+)\[\d*\])$")
_PRIMITIVES = {"boolean", "byte", "char", "float", "double", "float32", "float64", "int8", "uint8", "int16",
               "uint16", "int32", "uint32", "int64", "uint64", "string", "wstring", "octet"}
TIME_TYPES = {"builtin_interfaces/Time", "builtin_interfaces/Duration"}


def element_type(field_type: str) -> tuple[str, bool]:
    """(element type, is a sequence) of a rosidl field type (``sequence<pkg/X>``, ``int32[3]``…)."""
    match = _SEQUENCE.match(field_type.strip())
    if match:
        return (match.group(1) or match.group(2)).strip(), True
    base = field_type.strip()
    if base.startswith(("string<", "wstring<")):
        base = base.split("<", 1)[0]
    return base, False


def is_message_type(field_type: str) -> bool:
    base, _ = element_type(field_type)
    return "/" in base and base not in TIME_TYPES


def check_against(node: NodeMap, type_name: str, describe: Describe, where: str = "mapping") -> None:
    """MappingError naming the field and the type when ``node`` uses a field the type lacks, maps
    a nested message as a scalar, or a scalar as nested."""
    fields = describe(type_name)
    for group in ("fields", "timed"):
        for name in getattr(node, group):
            if name not in fields:
                raise MappingError(f"{where}.{group}.{name}",
                                   f"message type {type_name} has no field {name!r} (fields: {', '.join(fields)})")
            if is_message_type(fields[name]):
                raise MappingError(f"{where}.{group}.{name}", f"{type_name}.{name} is a nested message "
                                   f"({fields[name]}): map it under 'children'")
    for var in re.findall(r"{(\w+)}", node.subject or ""):
        if var not in fields:
            raise MappingError(f"{where}.subject", f"message type {type_name} has no field {var!r} "
                               f"(fields: {', '.join(fields)})")
    for name, (_link, child) in node.children.items():
        if name not in fields:
            raise MappingError(f"{where}.children.{name}",
                               f"message type {type_name} has no field {name!r} (fields: {', '.join(fields)})")
        if not is_message_type(fields[name]):
            raise MappingError(f"{where}.children.{name}", f"{type_name}.{name} is not a nested message "
                               f"({fields[name]}): map it under 'fields'")
        check_against(child, _qualified(element_type(fields[name])[0], type_name), describe,
                      f"{where}.children.{name}")


def introspected_spec(type_name: str, describe: Describe, depth: int = 0) -> dict[str, Any]:
    """A mapping derived from the type alone: ``printeps:<Type>`` nodes named by an ``id`` field,
    scalar fields as ``printeps:<field>``, nested messages and arrays of them as child nodes."""
    if depth > MAX_DEPTH:
        raise MappingError(type_name, f"nested deeper than {MAX_DEPTH} levels")
    fields = describe(type_name)
    local = type_name.rsplit("/", 1)[-1]
    spec: dict[str, Any] = {"subject": "printeps:{id}" if fields.get("id", "").startswith("string") else None,
                            "type": f"printeps:{local}", "fields": {}}
    children: dict[str, Any] = {}
    for name, field_type in fields.items():
        base, _seq = element_type(field_type)
        if base in TIME_TYPES:
            continue  # stamps become the event time, not a triple
        if is_message_type(field_type):
            children[name] = {"link": f"printeps:{name}",
                              **introspected_spec(_qualified(base, type_name), describe, depth + 1)}
        else:
            spec["fields"][name] = f"printeps:{name}"
    if children:
        spec["children"] = children
    return spec


def _qualified(base: str, parent: str) -> str:
    """``Customer`` inside ``pkg/msg/Entrance`` → ``pkg/msg/Customer``; ``pkg/Customer`` → ``pkg/msg/Customer``."""
    parts = base.split("/")
    if len(parts) == 1:
        return parent.rsplit("/", 1)[0] + "/" + base
    if len(parts) == 2:
        return f"{parts[0]}/msg/{parts[1]}"
    return base
