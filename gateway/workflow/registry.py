"""The workflows the gateway knows, with versions: replaced while running, like rule sets.

Why: domain experts edit a workflow and the next run must use it, without a restart and without
disturbing a run in progress. ``get`` hands out an immutable snapshot; ``replace`` validates the
new text completely, then stores it as a new version in the catalog (:mod:`gateway.base.versions`),
which every gateway process follows. Rollback moves the current pointer back, as for rule sets.
The ``workflows/`` folder is the seed: a workflow the catalog has never had is imported from it
at start (author "seed"); one the catalog has is never overwritten by files. Seeding, loading and
following other processes are the shared life cycle of :mod:`gateway.base.lifecycle`.
"""

from __future__ import annotations

import hashlib
import logging
from dataclasses import dataclass
from pathlib import Path

from gateway.base.lifecycle import CatalogLifecycle
from gateway.base.versions import Catalog, CatalogConflict, Version, VersionInfo, VersionMissing
from gateway.workflow.loader import Problem, WorkflowInvalid, parse
from gateway.workflow.model import Workflow

log = logging.getLogger(__name__)

KIND = "workflow"
RESERVED_NAMES = {"runs", "manual", "validate", "schema", "palette", "try"}


class WorkflowNotFound(LookupError):
    def __init__(self, name: str, version: int | None = None) -> None:
        what = f"workflow {name!r}" + (f" version {version}" if version is not None else "")
        super().__init__(f"{what} not found")
        self.name = name
        self.version = version


class WorkflowConflict(RuntimeError):
    """``base_version`` is not the current version any more: someone else edited meanwhile."""

    def __init__(self, name: str, current: int) -> None:
        super().__init__(f"workflow {name!r} is now at version {current}")
        self.name = name
        self.current = current


@dataclass(frozen=True)
class Entry:
    """One version of a workflow: its model (with ``source`` text) and who made it when."""

    workflow: Workflow
    info: VersionInfo


class WorkflowRegistry(CatalogLifecycle):
    """Workflow versions in a catalog, parsed once per version and kept for runs to use."""

    kind = KIND
    failures = (WorkflowInvalid, OSError, UnicodeDecodeError)
    seed_races = (WorkflowConflict,)

    def __init__(self, catalog: Catalog | None = None) -> None:
        super().__init__(catalog)
        self._parsed: dict[tuple[str, int], Entry] = {}

    # ------------------------------------------------------------ the seed folder

    def _seed_paths(self, folder: Path) -> list[Path]:
        return sorted(folder.glob("*.yaml"))

    def _read_seed(self, path: Path) -> tuple[str, Workflow]:
        """An invalid file is reported and skipped: the gateway starts with the others."""
        wf = parse(path.read_text(encoding="utf-8"), file=str(path))
        return wf.name, wf

    def _store_seed(self, name: str, item: Workflow, path: Path) -> int:
        # already parsed and checked: stored as it is, not parsed a second time
        return self._save(name, item, author="seed", comment=f"seeded from {path.name}", base_version=0).version

    # ------------------------------------------------------------ reading

    def names(self) -> list[str]:
        return self._served.names()

    def current(self, name: str) -> Entry:
        served = self.served(name)
        if served is None:
            self.sync(name)  # made by another process a moment ago, perhaps
            served = self.served(name)
            if served is None:
                raise WorkflowNotFound(name)
        return self.version(name, served[0])

    def get(self, name: str) -> Workflow:
        """The current workflow (an immutable snapshot a run can keep)."""
        return self.current(name).workflow

    def versions(self, name: str) -> list[VersionInfo]:
        infos = self.catalog.versions(KIND, name)
        if not infos:
            raise WorkflowNotFound(name)
        return infos

    def version(self, name: str, version: int) -> Entry:
        key = (name, int(version))
        with self._lock:
            entry = self._parsed.get(key)
        if entry is not None:
            return entry
        try:
            stored = self.catalog.load(KIND, name, int(version))
        except VersionMissing:
            raise WorkflowNotFound(name, version) from None
        return self._parse(stored)

    def _parse(self, stored: Version) -> Entry:
        """Parse a stored version once and keep it (a version never changes)."""
        key = (stored.info.name, stored.info.version)
        with self._lock:
            entry = self._parsed.get(key)
        if entry is None:
            entry = Entry(parse(stored.payload["text"], file=f"{stored.info.name}.yaml"), stored.info)
            with self._lock:
                self._parsed[key] = entry
        return entry

    def history(self, name: str) -> list[dict]:
        return [c.to_dict() for c in self.catalog.history(KIND, name)]

    # ------------------------------------------------------------ changing

    def replace(self, name: str, text: str, *, author: str = "anonymous", comment: str = "",
                base_version: int | None = None) -> VersionInfo:
        """Validate ``text`` and make it the current version of ``name`` (created if new).

        Raises :class:`WorkflowInvalid` (nothing changes) or :class:`WorkflowConflict` when
        ``base_version`` is stale.
        """
        return self._save(name, parse(text, file=f"{name}.yaml"), author=author, comment=comment,
                          base_version=base_version)

    def _save(self, name: str, wf: Workflow, *, author: str, comment: str, base_version: int | None) -> VersionInfo:
        """Store the parsed workflow ``wf`` (its text: ``wf.source``) as the current version of ``name``."""
        text = wf.source
        if wf.name != name:
            raise WorkflowInvalid([Problem(f"{name}.yaml", "workflow", *_place_of_name(text),
                                           f"the text defines workflow {wf.name!r}, not {name!r}")])
        if name in RESERVED_NAMES:
            raise WorkflowInvalid([Problem(f"{name}.yaml", "workflow", *_place_of_name(text),
                                           f"{name!r} is a reserved name")])
        try:
            info, seq = self.catalog.save(KIND, name, {"text": wf.source}, author=author, comment=comment,
                                          hash=_hash(wf.source), base_version=base_version)
        except CatalogConflict as conflict:
            raise WorkflowConflict(name, conflict.current) from None
        with self._lock:
            self._parsed[(name, info.version)] = Entry(wf, info)
        self._serve(name, info.version, seq)
        return info

    def rollback(self, name: str, version: int, *, author: str = "anonymous", comment: str = "") -> VersionInfo:
        """Make an earlier version current again (the pointer moves; history keeps the rollback)."""
        self.version(name, version)  # WorkflowNotFound when there is no such version
        info, seq = self.catalog.set_current(KIND, name, int(version), author=author,
                                             comment=comment or f"rollback to version {version}")
        self._serve(name, info.version, seq)
        return info

    def delete(self, name: str, *, author: str = "anonymous") -> None:
        try:
            seq = self.catalog.delete(KIND, name, author=author)
        except VersionMissing:
            raise WorkflowNotFound(name) from None
        self._serve(name, None, seq)

    def _serve(self, name: str, version: int | None, seq: int) -> None:
        """Serve ``version`` (None: stop) unless a newer catalog change is served already."""
        self._served.set(name, version, seq)

    # ------------------------------------------------------------ the shared life cycle's hooks

    def _apply(self, name: str, stored: Version, seq: int, *, elsewhere: bool) -> None:
        """Parse the new version now, not on the next run, then serve it."""
        self._parse(stored)
        self._serve(name, stored.info.version, seq)

    def _withdraw(self, name: str, seq: int) -> None:
        self._serve(name, None, seq)


def _hash(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def _place_of_name(text: str) -> tuple[int, int]:
    for number, line in enumerate(text.splitlines(), start=1):
        if line.startswith("workflow:"):
            return number, 1
    return 0, 0
