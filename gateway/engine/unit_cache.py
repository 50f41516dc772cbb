"""Compiled units of rule sets, cached by content in memory and on disk, shared between versions,
rule sets and processes.

Why: compiling DRL with Drools' executable model costs ~5 ms of CPU a rule; the compiled classes of
a rule depend only on its text and what it uses (see :mod:`gateway.engine.drl_items`). So every
unit's class bytes are kept under its content hash, with the keys of the rules it holds, and a
build takes each rule from wherever it was compiled before. Several gateway processes on one host
share the disk cache: files are written whole under a temporary name and renamed into place, so a
reader sees a complete unit or none; a unit that vanished (evicted by another process) is simply
compiled again. Gateways on other hosts share units through an optional third tier, ``shared``
(the Information State: :class:`gateway.store.unit_store.SharedUnitStore`, set by the composition
root): a unit or plan missing in memory and on disk is looked up there, and every unit and plan
written to disk is written there too.

Layout of ``<root>/<env>/`` (``env`` = Drools version + Java helpers + format, so classes made by
another Drools are never loaded):

- ``units/<id>.zip`` the unit's class files, ``units/<id>.json`` its manifest (written last);
- ``sets/<content hash>.json`` how a rule set that compiled is assembled from units (no parsing
  or compiling needed to load it again, e.g. at the next start).
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

FORMAT = 1
MAX_PLANS = 500


@dataclass
class UnitArtifact:
    """One compiled unit: its class bytes (zipped) and what it holds.

    ``rules`` maps each rule key to ``(package, rule name)``; a declarations unit holds no rules
    but the declared types, globals, functions and queries every rule unit is loaded against.
    """

    id: str
    kind: str  # "declarations" | "rules" | "whole" (a whole set in one unit)
    model_classes: list[str]
    rules: dict[str, tuple[str, str]]
    data: bytes  # the zipped class files (Units.zip)
    created: float = field(default_factory=time.time)

    def manifest(self) -> dict[str, Any]:
        return {"format": FORMAT, "id": self.id, "kind": self.kind, "model_classes": self.model_classes,
                "rules": {k: list(v) for k, v in self.rules.items()}, "created": self.created, "size": len(self.data)}

    @classmethod
    def from_manifest(cls, manifest: dict[str, Any], data: bytes) -> UnitArtifact:
        return cls(manifest["id"], manifest["kind"], list(manifest["model_classes"]),
                   {k: (v[0], v[1]) for k, v in manifest["rules"].items()}, data, manifest.get("created", 0.0))


@dataclass
class CacheStats:
    memory_hits: int = 0
    disk_hits: int = 0
    shared_hits: int = 0
    misses: int = 0
    written: int = 0
    evicted: int = 0


class UnitCache:
    """Units by id and rules by key, in memory (bounded, least recently used first out) and on disk
    (bounded by size, oldest first out). Thread-safe."""

    def __init__(self, root: Path | None, env: str, memory_mb: int = 256, disk_mb: int = 2048,
                 shared: Any = None):
        self.env = env
        self.shared = shared  # units and plans of other hosts (see the module's docstring), or None
        self.dir = (Path(root) / env) if root is not None else None
        self.memory_bytes = memory_mb * 1024 * 1024
        self.disk_bytes = disk_mb * 1024 * 1024
        self._units: OrderedDict[str, UnitArtifact] = OrderedDict()
        self._memory_used = 0
        self._rule_index: dict[str, str] = {}  # rule key -> unit id (memory or disk)
        self._disk_seen: set[str] = set()
        self._lock = threading.RLock()
        self.stats = CacheStats()
        if self.dir is not None:
            try:
                (self.dir / "units").mkdir(parents=True, exist_ok=True)
                (self.dir / "sets").mkdir(parents=True, exist_ok=True)
            except OSError as exc:  # a read-only home: work from memory only
                log.warning("rule unit cache %s not writable (%s): memory only", self.dir, exc)
                self.dir = None

    # ------------------------------------------------------------------ units

    def get(self, unit_id: str) -> UnitArtifact | None:
        with self._lock:
            unit = self._units.get(unit_id)
            if unit is not None:
                self._units.move_to_end(unit_id)
                self.stats.memory_hits += 1
                return unit
        unit = self._read(unit_id)
        if unit is not None:
            self.stats.disk_hits += 1
            self._remember(unit)
            return unit
        unit = self._read_shared(unit_id)
        if unit is None:
            self.stats.misses += 1
            return None
        self.stats.shared_hits += 1
        self._remember(unit)
        self._write(unit)  # this host's other processes find it on disk from now on
        return unit

    def put(self, unit: UnitArtifact, persist: bool = True) -> None:
        self._remember(unit)
        if persist:
            self._write(unit)
            if self.shared is not None:
                self.shared.put_unit(self.env, unit.manifest(), unit.data)

    def _read_shared(self, unit_id: str) -> UnitArtifact | None:
        if self.shared is None or self.dir is None:
            return None
        found = self.shared.get_unit(self.env, unit_id)
        if found is None:
            return None
        manifest, data = found
        if manifest.get("format") != FORMAT or manifest.get("size") != len(data) or manifest.get("id") != unit_id:
            log.warning("shared rule unit %s is not usable here (format or size differs); compiling it", unit_id)
            return None
        return UnitArtifact.from_manifest(manifest, data)

    def find_rule(self, rule_key: str) -> str | None:
        """The id of a unit holding the rule with this key, if any (as of the last :meth:`refresh`)."""
        with self._lock:
            return self._rule_index.get(rule_key)

    def refresh(self) -> None:
        """Learn the rules of units other processes wrote to disk since the last look (a build calls
        this once before looking its rules up)."""
        if self.dir is not None:
            self._scan_disk()

    def forget_rule(self, rule_key: str, unit_id: str) -> None:
        """The unit is gone (evicted elsewhere): stop pointing at it for this rule."""
        with self._lock:
            if self._rule_index.get(rule_key) == unit_id:
                del self._rule_index[rule_key]

    def _remember(self, unit: UnitArtifact) -> None:
        with self._lock:
            if unit.id not in self._units:
                self._units[unit.id] = unit
                self._memory_used += len(unit.data)
            self._units.move_to_end(unit.id)
            for key in unit.rules:
                self._rule_index.setdefault(key, unit.id)
            while self._memory_used > self.memory_bytes and len(self._units) > 1:
                _, old = self._units.popitem(last=False)
                self._memory_used -= len(old.data)
                if self.dir is None:  # nowhere else to find its rules
                    for key in old.rules:
                        if self._rule_index.get(key) == old.id:
                            del self._rule_index[key]

    # ------------------------------------------------------------------ disk

    def _unit_paths(self, unit_id: str) -> tuple[Path, Path]:
        assert self.dir is not None
        return self.dir / "units" / f"{unit_id}.zip", self.dir / "units" / f"{unit_id}.json"

    def _read(self, unit_id: str) -> UnitArtifact | None:
        if self.dir is None:
            return None
        data_path, manifest_path = self._unit_paths(unit_id)
        try:
            manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
            data = data_path.read_bytes()
        except (OSError, ValueError):
            return None
        if manifest.get("format") != FORMAT or manifest.get("size") != len(data):
            return None
        _touch(manifest_path)
        return UnitArtifact.from_manifest(manifest, data)

    def _write(self, unit: UnitArtifact) -> None:
        if self.dir is None:
            return
        data_path, manifest_path = self._unit_paths(unit.id)
        if manifest_path.exists():
            _touch(manifest_path)
            return
        try:
            _atomic_write(data_path, unit.data)
            _atomic_write(manifest_path, json.dumps(unit.manifest()).encode("utf-8"))  # last: marks it complete
            self.stats.written += 1
            with self._lock:
                self._disk_seen.add(unit.id)
        except OSError as exc:
            log.warning("could not write rule unit %s to %s: %s", unit.id, self.dir, exc)
            return
        self._evict_disk()

    def _scan_disk(self) -> None:
        """Index the rules of units other processes wrote since the last look."""
        assert self.dir is not None
        try:
            names = [e.name for e in os.scandir(self.dir / "units") if e.name.endswith(".json")]
        except OSError:
            return
        for name in names:
            unit_id = name[:-5]
            with self._lock:
                if unit_id in self._disk_seen:
                    continue
                self._disk_seen.add(unit_id)
            try:
                manifest = json.loads((self.dir / "units" / name).read_text(encoding="utf-8"))
            except (OSError, ValueError):
                continue
            if manifest.get("format") != FORMAT:
                continue
            with self._lock:
                for key in manifest.get("rules", {}):
                    self._rule_index.setdefault(key, unit_id)

    def _evict_disk(self) -> None:
        """Keep the disk cache under its bound: the units used least recently go first."""
        assert self.dir is not None
        try:
            entries = []
            total = 0
            for entry in os.scandir(self.dir / "units"):
                if entry.name.endswith(".zip"):
                    stat = entry.stat()
                    total += stat.st_size
                    manifest = self.dir / "units" / (entry.name[:-4] + ".json")
                    try:
                        used = manifest.stat().st_mtime
                    except OSError:
                        used = stat.st_mtime
                    entries.append((used, stat.st_size, entry.name[:-4]))
            if total <= self.disk_bytes:
                return
            for used, size, unit_id in sorted(entries):
                if total <= self.disk_bytes * 0.8:
                    break
                data_path, manifest_path = self._unit_paths(unit_id)
                for path in (manifest_path, data_path):  # manifest first: readers skip it from now on
                    try:
                        path.unlink()
                    except OSError:
                        pass
                total -= size
                self.stats.evicted += 1
        except OSError as exc:
            log.debug("disk eviction of %s failed: %s", self.dir, exc)

    # ------------------------------------------------------------------ rule set plans

    def get_plan(self, content_hash: str) -> dict[str, Any] | None:
        """How the rule set with this content hash was assembled (see :func:`put_plan`)."""
        if self.dir is None:
            return None
        path = self.dir / "sets" / f"{content_hash}.json"
        try:
            plan = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return self._shared_plan(content_hash)
        if plan.get("format") != FORMAT:
            return self._shared_plan(content_hash)
        _touch(path)
        return plan

    def _shared_plan(self, content_hash: str) -> dict[str, Any] | None:
        """The plan another host wrote (kept on this host's disk from now on)."""
        if self.shared is None:
            return None
        plan = self.shared.get_plan(self.env, content_hash)
        if plan is None or plan.get("format") != FORMAT:
            return None
        self._write_plan(content_hash, plan)
        return plan

    def put_plan(self, content_hash: str, plan: dict[str, Any]) -> None:
        if self.dir is None:
            return
        self._write_plan(content_hash, plan)
        if self.shared is not None:
            self.shared.put_plan(self.env, content_hash, {**plan, "format": FORMAT})

    def _write_plan(self, content_hash: str, plan: dict[str, Any]) -> None:
        assert self.dir is not None
        try:
            _atomic_write(self.dir / "sets" / f"{content_hash}.json", json.dumps({**plan, "format": FORMAT}).encode("utf-8"))
        except OSError as exc:
            log.warning("could not write the plan of rule set %s: %s", content_hash[:12], exc)
            return
        self._evict_plans()

    def _evict_plans(self) -> None:
        """Keep the newest MAX_PLANS plans (an edit session leaves one per version)."""
        assert self.dir is not None
        try:
            plans = [(e.stat().st_mtime, e.path) for e in os.scandir(self.dir / "sets") if e.name.endswith(".json")]
        except OSError:
            return
        if len(plans) <= MAX_PLANS:
            return
        for _, path in sorted(plans)[: len(plans) - MAX_PLANS]:
            try:
                os.unlink(path)
            except OSError:
                pass


def _atomic_write(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def _touch(path: Path) -> None:
    try:
        os.utime(path)
    except OSError:
        pass
