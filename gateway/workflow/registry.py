"""The workflows the gateway knows, with versions: replaced while running, like rule sets.

Why: domain experts edit a workflow and the next run must use it, without a restart and without
disturbing a run in progress. ``get`` hands out an immutable snapshot; ``replace`` validates the
new text completely, then swaps the snapshot under a lock. Versions are kept (in memory and, with
a data directory, on disk as ``<data>/workflows/<name>/v<N>.yaml`` + ``history.json``) so an edit
can be rolled back. The ``workflows/`` folder is the starting point: a file whose content changed
since it was last imported becomes a new version (author "filesystem").
"""

from __future__ import annotations

import hashlib
import json
import logging
import threading
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from gateway.workflow.loader import Problem, WorkflowInvalid, parse
from gateway.workflow.model import Workflow

log = logging.getLogger(__name__)

RESERVED_NAMES = {"runs", "manual", "validate", "schema"}


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
class VersionInfo:
    name: str
    version: int
    updated_at: str
    author: str
    comment: str
    hash: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class Entry:
    """One version of a workflow: its model (with ``source`` text) and who made it when."""

    workflow: Workflow
    info: VersionInfo


class WorkflowRegistry:
    def __init__(self, source_dir: str | Path | None = None, data_dir: str | Path | None = None) -> None:
        self.source_dir = Path(source_dir) if source_dir else None
        self.data_dir = Path(data_dir) / "workflows" if data_dir else None
        self._history: dict[str, list[Entry]] = {}
        self._imported: dict[str, str] = {}  # name -> hash of the source file last imported
        self._lock = threading.RLock()

    # ------------------------------------------------------------ loading

    def load(self) -> list[Problem]:
        """Load kept versions, then import changed files from the source folder; returns file problems.

        An invalid file is reported and skipped: the gateway starts with the others.
        """
        problems: list[Problem] = []
        with self._lock:
            self._load_kept()
            if self.source_dir is None or not self.source_dir.is_dir():
                return problems
            for path in sorted(self.source_dir.glob("*.yaml")):
                text = path.read_text(encoding="utf-8")
                digest = _hash(text)
                try:
                    wf = parse(text, file=str(path))
                except WorkflowInvalid as exc:
                    problems.extend(exc.problems)
                    continue
                if self._imported.get(wf.name) == digest:
                    continue
                self._add(wf, author="filesystem", comment=f"imported from {path.name}")
                self._imported[wf.name] = digest
                self._save_state(wf.name)
        return problems

    def _load_kept(self) -> None:
        if self.data_dir is None or not self.data_dir.is_dir():
            return
        for history_file in sorted(self.data_dir.glob("*/history.json")):
            state = json.loads(history_file.read_text(encoding="utf-8"))
            name = history_file.parent.name
            entries = []
            for item in state["versions"]:
                path = history_file.parent / f"v{item['version']}.yaml"
                try:
                    entries.append(Entry(parse(path.read_text(encoding="utf-8"), file=str(path)), VersionInfo(**item)))
                except WorkflowInvalid:  # e.g. written under an older schema: keep the versions that still load
                    log.error("kept workflow version %s no longer loads; skipped", path)
            if entries:
                self._history[name] = entries
            if state.get("imported_hash"):
                self._imported[name] = state["imported_hash"]

    # ------------------------------------------------------------ reading

    def names(self) -> list[str]:
        with self._lock:
            return sorted(self._history)

    def current(self, name: str) -> Entry:
        with self._lock:
            entries = self._history.get(name)
            if not entries:
                raise WorkflowNotFound(name)
            return entries[-1]

    def get(self, name: str) -> Workflow:
        """The current workflow (an immutable snapshot a run can keep)."""
        return self.current(name).workflow

    def versions(self, name: str) -> list[VersionInfo]:
        with self._lock:
            if name not in self._history:
                raise WorkflowNotFound(name)
            return [e.info for e in self._history[name]]

    def version(self, name: str, version: int) -> Entry:
        with self._lock:
            for entry in self._history.get(name, []):
                if entry.info.version == version:
                    return entry
        raise WorkflowNotFound(name, version)

    # ------------------------------------------------------------ changing

    def replace(self, name: str, text: str, *, author: str = "anonymous", comment: str = "",
                base_version: int | None = None) -> VersionInfo:
        """Validate ``text`` and make it the current version of ``name`` (created if new).

        Raises :class:`WorkflowInvalid` (nothing changes), :class:`WorkflowConflict` when
        ``base_version`` is stale, ``ValueError`` when the text names another workflow.
        """
        wf = parse(text, file=f"{name}.yaml")
        if wf.name != name:
            raise WorkflowInvalid([Problem(f"{name}.yaml", "workflow", *_place_of_name(text),
                                           f"the text defines workflow {wf.name!r}, not {name!r}")])
        if name in RESERVED_NAMES:
            raise WorkflowInvalid([Problem(f"{name}.yaml", "workflow", *_place_of_name(text),
                                           f"{name!r} is a reserved name")])
        with self._lock:
            current = self._history.get(name)
            if base_version is not None:
                now = current[-1].info.version if current else 0
                if base_version != now:
                    raise WorkflowConflict(name, now)
            info = self._add(wf, author=author, comment=comment)
            self._save_state(name)
            return info

    def rollback(self, name: str, version: int, *, author: str = "anonymous", comment: str = "") -> VersionInfo:
        """Make an earlier version current again (as a new version, so history only grows)."""
        old = self.version(name, version)
        return self.replace(name, old.workflow.source, author=author,
                            comment=comment or f"rollback to version {version}")

    def _add(self, wf: Workflow, *, author: str, comment: str) -> VersionInfo:
        entries = self._history.setdefault(wf.name, [])
        number = entries[-1].info.version + 1 if entries else 1
        info = VersionInfo(wf.name, number, datetime.now(timezone.utc).isoformat(timespec="milliseconds"),
                           author, comment, _hash(wf.source))
        entries.append(Entry(wf, info))
        if self.data_dir is not None:
            folder = self.data_dir / wf.name
            folder.mkdir(parents=True, exist_ok=True)
            (folder / f"v{number}.yaml").write_text(wf.source, encoding="utf-8")
        return info

    def _save_state(self, name: str) -> None:
        if self.data_dir is None:
            return
        folder = self.data_dir / name
        folder.mkdir(parents=True, exist_ok=True)
        state = {"imported_hash": self._imported.get(name),
                 "versions": [e.info.to_dict() for e in self._history[name]]}
        tmp = folder / "history.json.tmp"
        tmp.write_text(json.dumps(state, indent=1), encoding="utf-8")
        tmp.replace(folder / "history.json")


def _hash(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:16]


def _place_of_name(text: str) -> tuple[int, int]:
    for number, line in enumerate(text.splitlines(), start=1):
        if line.startswith("workflow:"):
            return number, 1
    return 0, 0
