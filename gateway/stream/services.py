"""Continuous queries, their rule bindings and the RDF mappings: versioned in the catalog, live in
every gateway process.

Why services around the stream engine and the mapper: a query registered over REST (or a binding
or mapping changed in the workbench) is a change an author makes, like a rule set deploy. It is
checked first — a query that does not parse, a binding that names an unknown fact type, a mapping
that names a field the message type lacks all fail with what and where, and change nothing —
then stored as a new version in the catalog (kinds ``query`` and ``mapping``), made live here,
and followed by every other process (``sync``). The files under ``ontology/queries`` (``*.rq``
plus ``<stem>.binding.yaml``) and ``ontology/mappings/*.yaml`` only seed an empty store.
"""

from __future__ import annotations

import hashlib
import json
import logging
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import yaml

from gateway.rdf.mapping import Mapper, MappingError, NodeMap, check_against, node_map_from_spec, spec_of
from gateway.stream.engine import QueryNotFound, StreamEngine, StreamError
from gateway.stream.lexer import QueryParseError
from gateway.stream.query import ParamSpec, parse_query
from gateway.stream.rules import BindingError, RuleBinding
from gateway.base.versions import Catalog, CatalogConflict, MemoryCatalog, Served, VersionInfo, VersionMissing

log = logging.getLogger(__name__)

QUERY = "query"
MAPPING = "mapping"
Describe = Callable[[str], dict[str, str]]


def _hash(payload: Any) -> str:
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode("utf-8")).hexdigest()[:16]


def _params_payload(params: list[ParamSpec] | None) -> list[dict[str, Any]] | None:
    return None if params is None else [p.to_dict() for p in params]


def _params_from(raw: list[dict[str, Any]] | None) -> list[ParamSpec] | None:
    if raw is None:
        return None
    return [ParamSpec(name=p["name"], sparql=p.get("sparql"), value=p.get("value")) for p in raw]


@dataclass
class QueryDefinition:
    """A query as it is registered: its text and the registration's options."""

    name: str
    text: str
    params: list[ParamSpec] | None = None
    binding: RuleBinding | None = None
    report: str | None = None


class QueryService:
    """Register, replace, bind and remove continuous queries through the catalog."""

    def __init__(self, engine: StreamEngine, catalog: Catalog | None = None) -> None:
        self.engine = engine
        self.catalog: Catalog = catalog if catalog is not None else MemoryCatalog()
        self._served = Served()
        self._lock = threading.RLock()

    # ---- changing -------------------------------------------------------------------------------
    def register(self, text: str, params: list[ParamSpec] | None = None, replace: bool = False,
                 binding: RuleBinding | None = None, *, report: str | None = None, author: str = "anonymous",
                 comment: str = "", base_version: int | None = None) -> dict[str, Any]:
        """Check, store and serve a query (``replace``: a new version of an existing one;
        ``report``: a report policy overriding the query's own; ``base_version``: the version the
        edit started from, 0 for a new query — CatalogConflict when someone saved meanwhile)."""
        name = parse_query(text, params).name
        with self._lock:
            head = self.catalog.head(QUERY, name)
            if head is not None and head.live and not replace:
                raise StreamError(f"a query named {name!r} is already registered")
            self._check(text, params, binding, report)
            payload = {"text": text, "params": _params_payload(params),
                       "binding": binding.to_dict() if binding else None, "report": report}
            info, seq = self.catalog.save(QUERY, name, payload, author=author, comment=comment, hash=_hash(payload),
                                          base_version=base_version)
            result = self._serve(name, payload, info.version, seq)
        return {**result, "version": info.version}

    def bind_rules(self, name: str, binding: RuleBinding | None, *, author: str = "anonymous") -> dict[str, Any]:
        """A new version of the query with this binding (None: unbound)."""
        with self._lock:
            payload = dict(self._current_payload(name))
            self._check(payload["text"], _params_from(payload.get("params")), binding, payload.get("report"))
            payload["binding"] = binding.to_dict() if binding else None
            info, seq = self.catalog.save(QUERY, name, payload, author=author,
                                          comment="rules bound" if binding else "rules unbound", hash=_hash(payload))
            return {**self._serve(name, payload, info.version, seq), "version": info.version}

    def unregister(self, name: str, *, author: str = "anonymous") -> None:
        with self._lock:
            try:
                seq = self.catalog.delete(QUERY, name, author=author)
            except VersionMissing:
                raise QueryNotFound(f"no query named {name!r}") from None
            self._drop(name, seq)

    def rollback(self, name: str, version: int, *, author: str = "anonymous") -> dict[str, Any]:
        with self._lock:
            stored = self.catalog.load(QUERY, name, int(version))
            self._check(stored.payload["text"], _params_from(stored.payload.get("params")),
                        _binding(stored.payload.get("binding")), stored.payload.get("report"))
            info, seq = self.catalog.set_current(QUERY, name, int(version), author=author,
                                                 comment=f"rollback to version {version}")
            return {**self._serve(name, stored.payload, info.version, seq), "version": info.version}

    def versions(self, name: str) -> list[VersionInfo]:
        infos = self.catalog.versions(QUERY, name)
        if not infos:
            raise QueryNotFound(f"no query named {name!r}")
        return infos

    def _current_payload(self, name: str) -> dict[str, Any]:
        head = self.catalog.head(QUERY, name)
        if head is None or not head.live:
            raise QueryNotFound(f"no query named {name!r}")
        return self.catalog.load(QUERY, name, head.current).payload  # type: ignore[arg-type]

    def validate(self, text: str, params: list[ParamSpec] | None = None, binding: RuleBinding | None = None,
                 report: str | None = None) -> dict[str, Any]:
        """The checks of :meth:`register` without storing or serving anything: the query as it would
        run (windows, report policy, fast path) and whether its name is taken (a save would then be
        a new version of it). Raises what registering would raise."""
        name = parse_query(text, params).name
        info = self._check(text, params, binding, report)
        head = self.catalog.head(QUERY, name)
        live = head is not None and head.live
        return {"name": name, "exists": live, "version": head.current if live else None, "query": info}

    def current_version(self, name: str) -> int | None:
        head = self.catalog.head(QUERY, name)
        return head.current if head is not None and head.live else None

    def version(self, name: str, version: int | None = None) -> dict[str, Any]:
        """One stored version (the current one when ``version`` is None): its info, its definition
        (``text``, ``params``, ``binding``, ``report``) and whether it is current."""
        current = self.current_version(name)
        wanted = current if version is None else int(version)
        if wanted is None:
            raise QueryNotFound(f"no query named {name!r}")
        try:
            stored = self.catalog.load(QUERY, name, wanted)
        except VersionMissing:
            raise QueryNotFound(f"query {name!r} has no version {wanted}") from None
        return {**stored.info.to_dict(), "text": stored.payload["text"], "params": stored.payload.get("params"),
                "binding": stored.payload.get("binding"), "report": stored.payload.get("report"),
                "current": wanted == current}

    def definitions(self) -> list[QueryDefinition]:
        """What every query served here was registered with (text, params, binding, report
        policy), as stored: what a stream replay registers again on its scratch engines."""
        out = []
        for name in self._served.names():
            served = self._served.get(name)
            if served is None or served[0] is None:
                continue
            try:
                payload = self.catalog.load(QUERY, name, served[0]).payload
            except VersionMissing:
                continue
            out.append(QueryDefinition(name, payload["text"], _params_from(payload.get("params")),
                                       _binding(payload.get("binding")), payload.get("report")))
        return out

    def _check(self, text: str, params: list[ParamSpec] | None, binding: RuleBinding | None,
               report: str | None = None) -> dict[str, Any]:
        """Register on a scratch engine with the same rules, ontology and providers: the same checks
        as the real registration, nothing live touched. Returns the query's info there."""
        scratch = StreamEngine(self.engine.settings, rules_engine=self.engine.rules_engine,
                               ontology=self.engine.ontology, providers=self.engine.providers)
        scratch.share_static_graphs(self.engine)
        return scratch.register(text, params, replace=True, binding=binding, report=report)

    # ---- serving --------------------------------------------------------------------------------
    def _serve(self, name: str, payload: dict[str, Any], version: int, seq: int) -> dict[str, Any]:
        if not self._served.accepts(name, seq):
            return self.engine.query_info(name)
        info = self.engine.register(payload["text"], _params_from(payload.get("params")), replace=True,
                                    binding=_binding(payload.get("binding")), report=payload.get("report"))
        self._served.set(name, version, seq)
        return info

    def _drop(self, name: str, seq: int) -> None:
        if not self._served.set(name, None, seq):
            return
        try:
            self.engine.unregister(name)
        except QueryNotFound:
            pass

    def sync(self, name: str) -> None:
        with self._lock:
            head = self.catalog.head(QUERY, name)
            if head is None or not head.live:
                self._drop(name, head.seq if head else 1 << 62)
                return
            if self._served.is_current(name, head):
                return
            stored = self.catalog.load(QUERY, name, head.current)  # type: ignore[arg-type]
            self._serve(name, stored.payload, head.current, head.seq)  # type: ignore[arg-type]

    def reconcile(self) -> None:
        names = {h.name for h in self.catalog.heads(QUERY)} | set(self._served.names())
        for name in sorted(names):
            try:
                self.sync(name)
            except (QueryParseError, StreamError, BindingError) as exc:
                log.error("query %s not served: %s", name, exc)

    def load(self) -> None:
        """Serve the catalog's current queries (at start); one that fails is logged and skipped."""
        self.reconcile()

    def seed(self, folder: str | Path | None) -> dict[str, str]:
        """``*.rq`` files (with ``<stem>.binding.yaml``) the catalog has never had become version 1."""
        report: dict[str, str] = {}
        if not folder or not Path(folder).is_dir():
            return report
        for path in sorted(Path(folder).glob("*.rq")):
            try:
                text = path.read_text(encoding="utf-8")
                name = parse_query(text).name
                sidecar = path.with_name(path.stem + ".binding.yaml")
                binding = RuleBinding.from_dict(yaml.safe_load(sidecar.read_text(encoding="utf-8")),
                                                str(sidecar.name)) if sidecar.exists() else None
            except (OSError, QueryParseError, BindingError, yaml.YAMLError) as exc:
                log.error("query file %s not seeded: %s", path, exc)
                report[path.name] = f"failed: {exc}"
                continue
            if self.catalog.head(QUERY, name) is not None:
                report[name] = "kept"
                continue
            payload = {"text": text, "params": None, "binding": binding.to_dict() if binding else None}
            try:
                self._check(text, None, binding)
                self.catalog.save(QUERY, name, payload, author="seed", comment=f"seeded from {path.name}",
                                  hash=_hash(payload), base_version=0)
                report[name] = "seeded v1"
            except CatalogConflict:
                report[name] = "kept (seeded by another process)"
            except (QueryParseError, StreamError, BindingError) as exc:
                log.error("query file %s not seeded: %s", path, exc)
                report[name] = f"failed: {exc}"
        return report


def _binding(raw: Any) -> RuleBinding | None:
    return None if raw is None else RuleBinding.from_dict(raw)


class MappingService:
    """Named message → RDF mappings (``ontology/mappings/*.yaml``), versioned in the catalog."""

    def __init__(self, mapper: Mapper, catalog: Catalog | None = None, describe: Describe | None = None) -> None:
        self.mapper = mapper
        self.catalog: Catalog = catalog if catalog is not None else MemoryCatalog()
        self.describe = describe  # message type -> its fields (rosidl), when ROS types are importable
        self._served = Served()
        self._specs: dict[str, dict[str, Any]] = {}
        self._lock = threading.RLock()

    def names(self) -> list[str]:
        return sorted(self.mapper.mappings)

    def get(self, name: str) -> dict[str, Any]:
        """A mapping's data form, its version and its message type."""
        if name not in self.mapper.mappings:
            raise MappingError("mapping", f"no mapping named {name!r}; known: {self.names()}")
        spec = self._specs.get(name) or spec_of(self.mapper.mappings[name])
        served = self._served.get(name)
        return {"name": name, "version": served[0] if served else None, "spec": spec}

    def check(self, name: str, spec: Any) -> NodeMap:
        """The NodeMap of ``spec``; MappingError naming the key, or the field and the message type."""
        node = node_map_from_spec(spec, "mapping", resolve=self.mapper.mappings, prefixes=self.mapper.prefixes)
        type_name = spec.get("message_type") if isinstance(spec, dict) else None
        if type_name is not None:
            if not isinstance(type_name, str) or type_name.count("/") != 2:
                raise MappingError("mapping.message_type", "must look like pkg/msg/Type")
            if self.describe is not None:
                check_against(node, type_name, self.describe)
        return node

    def replace(self, name: str, spec: dict[str, Any], *, author: str = "anonymous", comment: str = "",
                base_version: int | None = None) -> VersionInfo:
        with self._lock:
            node = self.check(name, spec)
            info, seq = self.catalog.save(MAPPING, name, spec, author=author, comment=comment, hash=_hash(spec),
                                          base_version=base_version)
            self._serve(name, spec, node, info.version, seq)
            return info

    def delete(self, name: str, *, author: str = "anonymous") -> None:
        with self._lock:
            try:
                seq = self.catalog.delete(MAPPING, name, author=author)
            except VersionMissing:
                raise MappingError("mapping", f"no stored mapping named {name!r}") from None
            self._drop(name, seq)

    def versions(self, name: str) -> list[VersionInfo]:
        return self.catalog.versions(MAPPING, name)

    def version(self, name: str, version: int) -> dict[str, Any]:
        """One stored version: its info, its spec and whether it is the current one."""
        try:
            stored = self.catalog.load(MAPPING, name, int(version))
        except VersionMissing:
            raise MappingError("mapping", f"mapping {name!r} has no version {version}") from None
        head = self.catalog.head(MAPPING, name)
        return {**stored.info.to_dict(), "spec": stored.payload,
                "current": bool(head and head.live and head.current == stored.info.version)}

    def rollback(self, name: str, version: int, *, author: str = "anonymous") -> VersionInfo:
        """Make a stored version current again (checked first, like a change)."""
        with self._lock:
            try:
                spec = self.catalog.load(MAPPING, name, int(version)).payload
            except VersionMissing:
                raise MappingError("mapping", f"mapping {name!r} has no version {version}") from None
            node = self.check(name, spec)
            info, seq = self.catalog.set_current(MAPPING, name, int(version), author=author,
                                                 comment=f"rollback to version {version}")
            self._serve(name, spec, node, info.version, seq)
            return info

    def _serve(self, name: str, spec: dict[str, Any], node: NodeMap, version: int, seq: int) -> None:
        if not self._served.set(name, version, seq):
            return
        self.mapper.mappings[name] = node
        self._specs[name] = spec

    def _drop(self, name: str, seq: int) -> None:
        if not self._served.set(name, None, seq):
            return
        self._specs.pop(name, None)
        self.mapper.mappings.pop(name, None)

    def sync(self, name: str) -> None:
        with self._lock:
            head = self.catalog.head(MAPPING, name)
            if head is None or not head.live:
                self._drop(name, head.seq if head else 1 << 62)
                return
            if self._served.is_current(name, head):
                return
            spec = self.catalog.load(MAPPING, name, head.current).payload  # type: ignore[arg-type]
            node = node_map_from_spec(spec, "mapping", resolve=self.mapper.mappings, prefixes=self.mapper.prefixes)
            self._serve(name, spec, node, head.current, head.seq)  # type: ignore[arg-type]

    def reconcile(self) -> None:
        for name in sorted({h.name for h in self.catalog.heads(MAPPING)} | set(self._served.names())):
            try:
                self.sync(name)
            except MappingError as exc:
                log.error("mapping %s not served: %s", name, exc)

    def load(self) -> None:
        self.reconcile()

    def seed(self, folder: str | Path | None) -> dict[str, str]:
        report: dict[str, str] = {}
        if not folder or not Path(folder).is_dir():
            return report
        for path in sorted(Path(folder).glob("*.yaml")):
            name = path.stem
            if self.catalog.head(MAPPING, name) is not None:
                report[name] = "kept"
                continue
            try:
                spec = yaml.safe_load(path.read_text(encoding="utf-8"))
                self.check(name, spec)
                self.catalog.save(MAPPING, name, spec, author="seed", comment=f"seeded from {path.name}",
                                  hash=_hash(spec), base_version=0)
                report[name] = "seeded v1"
            except CatalogConflict:
                report[name] = "kept (seeded by another process)"
            except (OSError, yaml.YAMLError, MappingError) as exc:
                log.error("mapping file %s not seeded: %s", path, exc)
                report[name] = f"failed: {exc}"
        return report
