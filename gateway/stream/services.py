"""Continuous queries, their rule bindings and the RDF mappings: versioned in the catalog, live in
every gateway process.

Why services around the stream engine and the mapper: a query registered over REST (or a binding
or mapping changed in the workbench) is a change an author makes, like a rule set deploy. It is
checked first — a query that does not parse, a binding that names an unknown fact type, a mapping
that names a field the message type lacks all fail with what and where, and change nothing —
then stored as a new version in the catalog (kinds ``query`` and ``mapping``), made live here,
and followed by every other process (``sync``). The files under ``ontology/queries`` (``*.rq``
plus ``<stem>.binding.yaml``) and ``ontology/mappings/*.yaml`` only seed an empty store.

The two services differ only in what they check and serve: the changes (check → store → serve),
rollbacks, deletes and stored versions are :class:`_CheckedItems`; seeding, loading and following
other processes are the shared life cycle of :mod:`gateway.base.lifecycle`.
"""

from __future__ import annotations

import hashlib
import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import yaml

from gateway.rdf.mapping import Mapper, MappingError, NodeMap, check_against, node_map_from_spec, spec_of
from gateway.stream.engine import QueryNotFound, StreamEngine, StreamError
from gateway.stream.lexer import QueryParseError
from gateway.stream.query import ParamSpec, parse_query
from gateway.stream.rules import BindingError, RuleBinding
from gateway.base.lifecycle import CatalogLifecycle
from gateway.base.versions import Catalog, Version, VersionInfo, VersionMissing

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


class _CheckedItems(CatalogLifecycle):
    """A change is checked, stored as a new version, then served here; a rollback is checked like
    a change; a stored version is served again by other processes without the author's checks."""

    def _not_found(self, name: str, version: int | None = None) -> Exception:
        """The error for an unknown item or version (each service names its own)."""
        raise NotImplementedError

    def _prepare(self, name: str, payload: Any) -> Any:
        """Check ``payload`` as an author's change; returns what :meth:`_serve` needs."""
        raise NotImplementedError

    def _prepare_stored(self, name: str, payload: Any) -> Any:
        """What :meth:`_serve` needs for a version already stored (checked when it was made)."""
        raise NotImplementedError

    def _serve(self, name: str, payload: Any, prepared: Any, version: int, seq: int) -> Any:
        """Serve a version unless a newer change is served already."""
        raise NotImplementedError

    def _change(self, name: str, payload: Any, *, author: str, comment: str,
                base_version: int | None = None) -> tuple[VersionInfo, Any]:
        """Check, store and serve a new version; CatalogConflict when ``base_version`` is stale."""
        with self._lock:
            prepared = self._prepare(name, payload)
            info, seq = self.catalog.save(self.kind, name, payload, author=author, comment=comment,
                                          hash=_hash(payload), base_version=base_version)
            return info, self._serve(name, payload, prepared, info.version, seq)

    def _rollback(self, name: str, version: int, *, author: str) -> tuple[VersionInfo, Any]:
        """Make a stored version current again (checked first, like a change)."""
        with self._lock:
            payload = self._stored(name, int(version)).payload
            prepared = self._prepare(name, payload)
            info, seq = self.catalog.set_current(self.kind, name, int(version), author=author,
                                                 comment=f"rollback to version {version}")
            return info, self._serve(name, payload, prepared, info.version, seq)

    def _remove(self, name: str, *, author: str) -> None:
        with self._lock:
            try:
                seq = self.catalog.delete(self.kind, name, author=author)
            except VersionMissing:
                raise self._not_found(name) from None
            self._withdraw(name, seq)

    def _stored(self, name: str, version: int) -> Version:
        try:
            return self.catalog.load(self.kind, name, version)
        except VersionMissing:
            raise self._not_found(name, version) from None

    def current_version(self, name: str) -> int | None:
        head = self.catalog.head(self.kind, name)
        return head.current if head is not None and head.live else None

    def _apply(self, name: str, stored: Version, seq: int, *, elsewhere: bool) -> None:
        with self._lock:
            self._serve(name, stored.payload, self._prepare_stored(name, stored.payload), stored.info.version, seq)


class QueryService(_CheckedItems):
    """Register, replace, bind and remove continuous queries through the catalog."""

    kind = QUERY
    failures = (OSError, UnicodeDecodeError, QueryParseError, StreamError, BindingError, yaml.YAMLError)

    def __init__(self, engine: StreamEngine, catalog: Catalog | None = None) -> None:
        super().__init__(catalog)
        self.engine = engine

    # ---- changing -------------------------------------------------------------------------------
    def register(self, text: str, params: list[ParamSpec] | None = None, replace: bool = False,
                 binding: RuleBinding | None = None, *, report: str | None = None, author: str = "anonymous",
                 comment: str = "", base_version: int | None = None) -> dict[str, Any]:
        """Check, store and serve a query (``replace``: a new version of an existing one;
        ``report``: a report policy overriding the query's own; ``base_version``: the version the
        edit started from, 0 for a new query — CatalogConflict when someone saved meanwhile)."""
        name = parse_query(text, params).name
        with self._lock:
            if self.current_version(name) is not None and not replace:
                raise StreamError(f"a query named {name!r} is already registered")
            payload = {"text": text, "params": _params_payload(params),
                       "binding": binding.to_dict() if binding else None, "report": report}
            info, result = self._change(name, payload, author=author, comment=comment, base_version=base_version)
        return {**result, "version": info.version}

    def bind_rules(self, name: str, binding: RuleBinding | None, *, author: str = "anonymous") -> dict[str, Any]:
        """A new version of the query with this binding (None: unbound)."""
        with self._lock:
            payload = dict(self._current_payload(name))
            payload["binding"] = binding.to_dict() if binding else None
            info, result = self._change(name, payload, author=author,
                                        comment="rules bound" if binding else "rules unbound")
            return {**result, "version": info.version}

    def unregister(self, name: str, *, author: str = "anonymous") -> None:
        self._remove(name, author=author)

    def rollback(self, name: str, version: int, *, author: str = "anonymous") -> dict[str, Any]:
        info, result = self._rollback(name, version, author=author)
        return {**result, "version": info.version}

    def versions(self, name: str) -> list[VersionInfo]:
        infos = self.catalog.versions(QUERY, name)
        if not infos:
            raise self._not_found(name)
        return infos

    def _current_payload(self, name: str) -> dict[str, Any]:
        current = self.current_version(name)
        if current is None:
            raise self._not_found(name)
        return self.catalog.load(QUERY, name, current).payload

    def validate(self, text: str, params: list[ParamSpec] | None = None, binding: RuleBinding | None = None,
                 report: str | None = None) -> dict[str, Any]:
        """The checks of :meth:`register` without storing or serving anything: the query as it would
        run (windows, report policy, fast path) and whether its name is taken (a save would then be
        a new version of it). Raises what registering would raise."""
        name = parse_query(text, params).name
        info = self._check(text, params, binding, report)
        current = self.current_version(name)
        return {"name": name, "exists": current is not None, "version": current, "query": info}

    def version(self, name: str, version: int | None = None) -> dict[str, Any]:
        """One stored version (the current one when ``version`` is None): its info, its definition
        (``text``, ``params``, ``binding``, ``report``) and whether it is current."""
        current = self.current_version(name)
        wanted = current if version is None else int(version)
        if wanted is None:
            raise self._not_found(name)
        stored = self._stored(name, wanted)
        return {**stored.info.to_dict(), "text": stored.payload["text"], "params": stored.payload.get("params"),
                "binding": stored.payload.get("binding"), "report": stored.payload.get("report"),
                "current": wanted == current}

    def definitions(self) -> list[QueryDefinition]:
        """What every query served here was registered with (text, params, binding, report
        policy), as stored: what a stream replay registers again on its scratch engines."""
        out = []
        for name in self._served.names():
            served = self._served.get(name)
            if served is None:
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
    def _not_found(self, name: str, version: int | None = None) -> Exception:
        return QueryNotFound(f"no query named {name!r}" if version is None else
                             f"query {name!r} has no version {version}")

    def _prepare(self, name: str, payload: dict[str, Any]) -> None:
        self._check(payload["text"], _params_from(payload.get("params")), _binding(payload.get("binding")),
                    payload.get("report"))

    def _prepare_stored(self, name: str, payload: dict[str, Any]) -> None:
        return None  # the stream engine's registration parses it again

    def _serve(self, name: str, payload: dict[str, Any], prepared: None, version: int, seq: int) -> dict[str, Any]:
        if not self._served.accepts(name, seq):
            return self.engine.query_info(name)
        info = self.engine.register(payload["text"], _params_from(payload.get("params")), replace=True,
                                    binding=_binding(payload.get("binding")), report=payload.get("report"))
        self._served.set(name, version, seq)
        return info

    def _withdraw(self, name: str, seq: int) -> None:
        with self._lock:
            if not self._served.set(name, None, seq):
                return
            try:
                self.engine.unregister(name)
            except QueryNotFound:
                pass

    # ---- the seed folder ------------------------------------------------------------------------
    def _seed_paths(self, folder: Path) -> list[Path]:
        """``*.rq`` files, each with its ``<stem>.binding.yaml`` when there is one."""
        return sorted(folder.glob("*.rq"))

    def _read_seed(self, path: Path) -> tuple[str, dict[str, Any]]:
        text = path.read_text(encoding="utf-8")
        sidecar = path.with_name(path.stem + ".binding.yaml")
        binding = RuleBinding.from_dict(yaml.safe_load(sidecar.read_text(encoding="utf-8")),
                                        str(sidecar.name)) if sidecar.exists() else None
        return parse_query(text).name, {"text": text, "params": None,
                                        "binding": binding.to_dict() if binding else None}

    def _store_seed(self, name: str, item: dict[str, Any], path: Path) -> int:
        self._prepare(name, item)
        return self._save_seed(name, item, _hash(item), path)


def _binding(raw: Any) -> RuleBinding | None:
    return None if raw is None else RuleBinding.from_dict(raw)


class MappingService(_CheckedItems):
    """Named message → RDF mappings (``ontology/mappings/*.yaml``), versioned in the catalog."""

    kind = MAPPING
    failures = (OSError, UnicodeDecodeError, yaml.YAMLError, MappingError)

    def __init__(self, mapper: Mapper, catalog: Catalog | None = None, describe: Describe | None = None) -> None:
        super().__init__(catalog)
        self.mapper = mapper
        self.describe = describe  # message type -> its fields (rosidl), when ROS types are importable
        self._specs: dict[str, dict[str, Any]] = {}

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
        return self._change(name, spec, author=author, comment=comment, base_version=base_version)[0]

    def delete(self, name: str, *, author: str = "anonymous") -> None:
        self._remove(name, author=author)

    def versions(self, name: str) -> list[VersionInfo]:
        return self.catalog.versions(MAPPING, name)

    def version(self, name: str, version: int) -> dict[str, Any]:
        """One stored version: its info, its spec and whether it is the current one."""
        stored = self._stored(name, int(version))
        return {**stored.info.to_dict(), "spec": stored.payload,
                "current": self.current_version(name) == stored.info.version}

    def rollback(self, name: str, version: int, *, author: str = "anonymous") -> VersionInfo:
        """Make a stored version current again (checked first, like a change)."""
        return self._rollback(name, version, author=author)[0]

    # ---- serving --------------------------------------------------------------------------------
    def _not_found(self, name: str, version: int | None = None) -> Exception:
        return MappingError("mapping", f"no stored mapping named {name!r}" if version is None else
                            f"mapping {name!r} has no version {version}")

    def _prepare(self, name: str, payload: Any) -> NodeMap:
        return self.check(name, payload)

    def _prepare_stored(self, name: str, payload: Any) -> NodeMap:
        return node_map_from_spec(payload, "mapping", resolve=self.mapper.mappings, prefixes=self.mapper.prefixes)

    def _serve(self, name: str, payload: dict[str, Any], prepared: NodeMap, version: int, seq: int) -> None:
        if not self._served.set(name, version, seq):
            return
        self.mapper.mappings[name] = prepared
        self._specs[name] = payload

    def _withdraw(self, name: str, seq: int) -> None:
        with self._lock:
            if not self._served.set(name, None, seq):
                return
            self._specs.pop(name, None)
            self.mapper.mappings.pop(name, None)

    # ---- the seed folder ------------------------------------------------------------------------
    def _seed_paths(self, folder: Path) -> list[Path]:
        return sorted(folder.glob("*.yaml"))

    def _read_seed(self, path: Path) -> tuple[str, None]:
        return path.stem, None  # the file is read only when the catalog lacks the mapping

    def _store_seed(self, name: str, item: None, path: Path) -> int:
        spec = yaml.safe_load(path.read_text(encoding="utf-8"))
        self.check(name, spec)
        return self._save_seed(name, spec, _hash(spec), path)
