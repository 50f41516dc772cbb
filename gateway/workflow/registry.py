"""The workflows the gateway knows, with versions: replaced while running, like rule sets.

Why: domain experts edit a workflow and the next run must use it, without a restart and without
disturbing a run in progress. ``get`` hands out an immutable snapshot; ``replace`` validates the
new text completely, then stores it as a new version in the catalog (:mod:`gateway.base.versions`),
which every gateway process follows. Rollback moves the current pointer back, as for rule sets.
The ``workflows/`` folder is the seed: a workflow the catalog has never had is imported from it
at start (author "seed"); one the catalog has is never overwritten by files.
"""

from __future__ import annotations

import hashlib
import logging
import threading
from dataclasses import dataclass
from pathlib import Path

from gateway.base.versions import Catalog, CatalogConflict, MemoryCatalog, VersionInfo, VersionMissing
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


class WorkflowRegistry:
    """Workflow versions in a catalog, parsed once per version and kept for runs to use."""

    def __init__(self, catalog: Catalog | None = None, source_dir: str | Path | None = None) -> None:
        self.catalog: Catalog = catalog if catalog is not None else MemoryCatalog()
        self.source_dir = Path(source_dir) if source_dir else None
        self._parsed: dict[tuple[str, int], Entry] = {}
        self._current: dict[str, tuple[int, int]] = {}  # name -> (version, catalog seq): what this process serves
        self._lock = threading.RLock()

    # ------------------------------------------------------------ the seed folder

    def seed(self) -> list[Problem]:
        """Import the source folder's workflows the catalog has never had; returns file problems.
        An invalid file is reported and skipped: the gateway starts with the others."""
        problems: list[Problem] = []
        if self.source_dir is None or not self.source_dir.is_dir():
            return problems
        for path in sorted(self.source_dir.glob("*.yaml")):
            try:
                wf = parse(path.read_text(encoding="utf-8"), file=str(path))
            except WorkflowInvalid as exc:
                problems.extend(exc.problems)
                continue
            if self.catalog.head(KIND, wf.name) is not None:
                continue
            try:  # already parsed and checked above: stored as it is, not parsed a second time
                self._save(wf.name, wf, author="seed", comment=f"seeded from {path.name}", base_version=0)
            except WorkflowConflict:
                pass  # another process seeded it at the same moment
        return problems

    # ------------------------------------------------------------ reading

    def load(self) -> None:
        """Take the current version of every workflow from the catalog (at start)."""
        self.reconcile()

    def names(self) -> list[str]:
        with self._lock:
            return sorted(self._current)

    def current(self, name: str) -> Entry:
        with self._lock:
            served = self._current.get(name)
        if served is None:
            self.sync(name)  # made by another process a moment ago, perhaps
            with self._lock:
                served = self._current.get(name)
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
        entry = Entry(parse(stored.payload["text"], file=f"{name}.yaml"), stored.info)
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
        with self._lock:
            served = self._current.get(name)
            if served is not None and served[1] > seq:
                return
            if version is None:
                self._current.pop(name, None)
            else:
                self._current[name] = (version, seq)

    # ------------------------------------------------------------ following other processes

    def sync(self, name: str) -> None:
        """Converge to the catalog's head (parsing the new version now, not on the next run)."""
        head = self.catalog.head(KIND, name)
        if head is None or not head.live:
            self._serve(name, None, head.seq if head else 1 << 62)
            return
        self.version(name, head.current)  # type: ignore[arg-type]
        self._serve(name, head.current, head.seq)

    def reconcile(self) -> None:
        with self._lock:
            known = set(self._current)
        for name in sorted(known | {h.name for h in self.catalog.heads(KIND)}):
            self.sync(name)


def _hash(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def _place_of_name(text: str) -> tuple[int, int]:
    for number, line in enumerate(text.splitlines(), start=1):
        if line.startswith("workflow:"):
            return number, 1
    return 0, 0
