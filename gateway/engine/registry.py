"""The version store: every deployed version of every rule set, on disk.

Layout under ``<data_dir>/registry/<name>/``::

    state.json                 {"current": 3, "deleted": false}
    versions/<n>/meta.json     name, version, deployed_at, author, comment, hash, files
    versions/<n>/files/<file>  the rule set's files as deployed
    history.jsonl              one line per deploy / rollback / delete

Why a plain directory: versions must survive restarts and be readable by an operator with ``ls``
and ``cat``. Every write goes to a temporary name first and is renamed into place, so a crash
leaves either the old or the new state, never half a version. Nothing is ever removed: a deleted
rule set keeps its history, and deploying it again continues its numbering.
"""

from __future__ import annotations

import json
import os
import threading
import time
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from gateway.engine.errors import VersionNotFound
from gateway.engine.ruleset import read_file, write_file


@dataclass(frozen=True)
class VersionInfo:
    """What is known about one deployed version (without its files)."""

    name: str
    version: int
    deployed_at: str
    author: str
    comment: str
    hash: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class RuleSetVersion:
    """A version with its files."""

    info: VersionInfo
    files: dict[str, str]

    def to_dict(self) -> dict[str, Any]:
        return {**self.info.to_dict(), "files": dict(self.files)}


@dataclass(frozen=True)
class RuleSetState:
    current: int | None
    deleted: bool


def _now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _write_json_atomic(path: Path, data: Any) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{threading.get_ident()}.tmp")
    tmp.write_text(json.dumps(data, indent=1, ensure_ascii=False), encoding="utf-8")
    os.replace(tmp, path)


class VersionStore:
    """Directory-backed store of rule set versions. Thread-safe for one process."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)
        self._lock = threading.RLock()

    def _dir(self, name: str) -> Path:
        return self.root / name

    def names(self) -> list[str]:
        return sorted(p.name for p in self.root.iterdir() if (p / "state.json").exists())

    def state(self, name: str) -> RuleSetState:
        path = self._dir(name) / "state.json"
        if not path.exists():
            return RuleSetState(current=None, deleted=False)
        data = json.loads(path.read_text(encoding="utf-8"))
        return RuleSetState(current=data.get("current"), deleted=bool(data.get("deleted")))

    def set_state(self, name: str, current: int | None, deleted: bool = False) -> None:
        with self._lock:
            self._dir(name).mkdir(parents=True, exist_ok=True)
            _write_json_atomic(self._dir(name) / "state.json", {"current": current, "deleted": deleted})

    def version_numbers(self, name: str) -> list[int]:
        vdir = self._dir(name) / "versions"
        if not vdir.exists():
            return []
        return sorted(int(p.name) for p in vdir.iterdir() if p.name.isdigit() and (p / "meta.json").exists())

    def save_version(self, name: str, files: dict[str, str], author: str, comment: str, content_hash: str) -> VersionInfo:
        """Writes a new version (it does not become current: see :meth:`set_state`)."""
        with self._lock:
            numbers = self.version_numbers(name)
            version = (numbers[-1] if numbers else 0) + 1
            info = VersionInfo(name, version, _now_iso(), author, comment, content_hash)
            vdir = self._dir(name) / "versions"
            vdir.mkdir(parents=True, exist_ok=True)
            tmp = vdir / f".{version}.tmp{os.getpid()}"
            (tmp / "files").mkdir(parents=True, exist_ok=True)
            for fname, text in files.items():  # tests/<name>.yaml in a subfolder; a workbook as itself
                write_file(tmp / "files" / fname, text)
            (tmp / "meta.json").write_text(
                json.dumps({**info.to_dict(), "files": sorted(files)}, indent=1, ensure_ascii=False), encoding="utf-8"
            )
            os.rename(tmp, vdir / str(version))
            return info

    def info(self, name: str, version: int) -> VersionInfo:
        meta = self._dir(name) / "versions" / str(version) / "meta.json"
        if not meta.exists():
            raise VersionNotFound(name, version)
        data = json.loads(meta.read_text(encoding="utf-8"))
        return VersionInfo(**{k: data[k] for k in ("name", "version", "deployed_at", "author", "comment", "hash")})

    def load(self, name: str, version: int) -> RuleSetVersion:
        info = self.info(name, version)
        fdir = self._dir(name) / "versions" / str(version) / "files"
        files = {p.relative_to(fdir).as_posix(): read_file(p) for p in sorted(fdir.rglob("*")) if p.is_file()}
        return RuleSetVersion(info, files)

    def list_versions(self, name: str) -> list[VersionInfo]:
        return [self.info(name, v) for v in self.version_numbers(name)]

    def append_history(self, name: str, event: dict[str, Any]) -> None:
        with self._lock:
            self._dir(name).mkdir(parents=True, exist_ok=True)
            line = json.dumps({"at": _now_iso(), "ts": time.time(), **event}, ensure_ascii=False)
            with open(self._dir(name) / "history.jsonl", "a", encoding="utf-8") as fh:
                fh.write(line + "\n")

    def history(self, name: str) -> list[dict[str, Any]]:
        path = self._dir(name) / "history.jsonl"
        if not path.exists():
            return []
        return [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
