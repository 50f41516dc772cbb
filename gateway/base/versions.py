"""Versioned things an author changes — rule sets, workflows, knowledge, queries, mappings — and the
change log that lets every gateway process follow every change.

Why one catalog for all of them: a deploy, a rollback or a delete means the same thing whatever is
deployed (a new numbered version, a pointer moved back, serving stopped; history kept forever), and
every process must see each of them within a second. The catalog keeps, per ``(kind, name)``:

- its versions (immutable: number, author, comment, content hash, payload);
- a head: which version is current (or that it was deleted), the last version number used, and
  the sequence number of the change that last moved it;
- a change log: one entry per deploy / rollback / delete (and per refusal by the rule policy:
  ``refused``, which changes nothing and is there for the audit), numbered by a global sequence,
  each with who (``author``), in which role and from which process (``origin``). Other
  processes read it to learn *what* changed; they then read the head to learn *how things are
  now* (level-triggered: a missed or repeated entry can never leave a process on a wrong version,
  and a periodic reconcile catches anything a crash left unannounced).

The source of truth is the Information State (:class:`gateway.store.catalog.MongoCatalog`);
:class:`MemoryCatalog` serves a single process with no database (local CLI commands, unit tests).
Plain Python: nothing here needs the JVM, MongoDB or HTTP.
"""

from __future__ import annotations

import copy
import threading
import time
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from typing import Any, Protocol

KINDS = ("ruleset", "workflow", "knowledge", "query", "mapping")


def now_iso() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds").replace("+00:00", "Z")


@dataclass(frozen=True)
class VersionInfo:
    """What is known about one version (without its content)."""

    name: str
    version: int
    deployed_at: str
    author: str
    comment: str
    hash: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class Version:
    """A version with its content (a rule set's files, a workflow's text, a query's definition…)."""

    info: VersionInfo
    payload: Any


@dataclass(frozen=True)
class Head:
    """Where ``(kind, name)`` stands: its current version (None when deleted) and its last change."""

    kind: str
    name: str
    current: int | None
    deleted: bool
    last: int
    seq: int

    @property
    def live(self) -> bool:
        return self.current is not None and not self.deleted


@dataclass(frozen=True)
class Change:
    """One entry of the change log (also the history of its item)."""

    seq: int
    kind: str
    name: str
    event: str  # deploy | rollback | delete | refused (by the rule policy: nothing changed)
    version: int | None
    author: str
    comment: str
    at: str
    ts: float
    origin: str = ""  # the process (host:pid, or the gateway's name) that made the change
    role: str = ""  # the principal's role (developer, author, caller), "local" for the gateway itself

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


class CatalogConflict(Exception):
    """``base_version`` is not the current version any more (someone deployed meanwhile)."""

    def __init__(self, kind: str, name: str, base: int, current: int) -> None:
        super().__init__(f"{kind} {name!r}: base version {base} is not current (current: {current})")
        self.kind, self.name, self.base, self.current = kind, name, base, current


class CatalogUnavailable(RuntimeError):
    """The catalog's database cannot be reached: nothing can be deployed right now."""


class VersionMissing(LookupError):
    """No such item or version in the catalog."""

    def __init__(self, kind: str, name: str, version: int | None = None) -> None:
        what = f"{kind} {name!r}" + (f" version {version}" if version is not None else "")
        super().__init__(f"{what} not found")
        self.kind, self.name, self.version = kind, name, version


class Catalog(Protocol):
    """What the services need from the catalog (see the module docstring)."""

    def head(self, kind: str, name: str) -> Head | None: ...

    def heads(self, kind: str) -> list[Head]: ...

    def save(self, kind: str, name: str, payload: Any, *, author: str, comment: str, hash: str,
             base_version: int | None = None, role: str = "") -> tuple[VersionInfo, int]:
        """Store a new version and make it current; returns it and the change's sequence number.
        ``base_version`` (0 = "nothing deployed yet") raises CatalogConflict when stale."""
        ...

    def set_current(self, kind: str, name: str, version: int, *, author: str, comment: str,
                    role: str = "") -> tuple[VersionInfo, int]:
        """Make a stored version current again (a rollback)."""
        ...

    def delete(self, kind: str, name: str, *, author: str, role: str = "") -> int:
        """Stop serving ``(kind, name)``; versions and history stay."""
        ...

    def refuse(self, kind: str, name: str, *, author: str, role: str, comment: str) -> int:
        """Log that a change by ``author`` was refused (``event: "refused"``); nothing else moves."""
        ...

    def load(self, kind: str, name: str, version: int) -> Version: ...

    def versions(self, kind: str, name: str) -> list[VersionInfo]: ...

    def history(self, kind: str, name: str) -> list[Change]: ...

    def changes_since(self, seq: int, limit: int = 1000) -> list[Change]:
        """Log entries with a sequence number above ``seq``, in order."""
        ...

    def last_seq(self) -> int: ...

    def wait_for_change(self, after_seq: int, timeout_s: float) -> None:
        """Block until a change after ``after_seq`` may exist, or ``timeout_s`` passed."""
        ...


class Served:
    """What one process serves of one kind: ``name -> (version, seq)`` of the catalog change it
    follows, with the one rule every service needs — only a newer change replaces what is served
    (a deploy answered here and the follower's sync of it may race; the later change wins)."""

    def __init__(self) -> None:
        self._items: dict[str, tuple[int, int]] = {}
        self._lock = threading.Lock()

    def get(self, name: str) -> tuple[int, int] | None:
        with self._lock:
            return self._items.get(name)

    def names(self) -> list[str]:
        with self._lock:
            return sorted(self._items)

    def accepts(self, name: str, seq: int) -> bool:
        """No newer change than ``seq`` is served for ``name``."""
        with self._lock:
            served = self._items.get(name)
            return served is None or served[1] <= seq

    def set(self, name: str, version: int | None, seq: int) -> bool:
        """Serve ``version`` (None: nothing) from change ``seq``; False when a newer one is served."""
        with self._lock:
            served = self._items.get(name)
            if served is not None and served[1] > seq:
                return False
            if version is None:
                self._items.pop(name, None)
            else:
                self._items[name] = (version, seq)
            return True


# --------------------------------------------------------------------------- in memory


@dataclass
class _Item:
    versions: list[Version] = field(default_factory=list)
    current: int | None = None
    deleted: bool = False
    seq: int = 0


class MemoryCatalog:
    """The catalog of one process with no database: the same contract, kept in memory."""

    def __init__(self, origin: str = "local") -> None:
        self.origin = origin
        self._items: dict[tuple[str, str], _Item] = {}
        self._log: list[Change] = []
        self._lock = threading.Condition()

    def sharing(self, origin: str) -> "MemoryCatalog":
        """Another process's catalog over this one's versions and log (one shared source, the
        in-memory stand-in for one database): its changes carry its own origin, so tests of two
        processes run over two objects, not one object twice."""
        other = MemoryCatalog(origin)
        other._items, other._log, other._lock = self._items, self._log, self._lock
        return other

    def head(self, kind: str, name: str) -> Head | None:
        with self._lock:
            item = self._items.get((kind, name))
            if item is None:
                return None
            return Head(kind, name, item.current, item.deleted, len(item.versions), item.seq)

    def heads(self, kind: str) -> list[Head]:
        with self._lock:
            names = sorted(n for k, n in self._items if k == kind)
        return [h for h in (self.head(kind, n) for n in names) if h is not None]

    def save(self, kind: str, name: str, payload: Any, *, author: str, comment: str, hash: str,
             base_version: int | None = None, role: str = "") -> tuple[VersionInfo, int]:
        with self._lock:
            item = self._items.setdefault((kind, name), _Item())
            current = item.current if not item.deleted else None
            if base_version is not None and int(base_version) != (current or 0):
                raise CatalogConflict(kind, name, int(base_version), current or 0)
            info = VersionInfo(name, len(item.versions) + 1, now_iso(), author, comment, hash)
            item.versions.append(Version(info, copy.deepcopy(payload)))
            item.current, item.deleted = info.version, False
            seq = self._append(kind, name, "deploy", info.version, author, comment, role)
            item.seq = seq
            return info, seq

    def set_current(self, kind: str, name: str, version: int, *, author: str, comment: str,
                    role: str = "") -> tuple[VersionInfo, int]:
        with self._lock:
            stored = self.load(kind, name, version)
            item = self._items[(kind, name)]
            item.current, item.deleted = version, False
            item.seq = self._append(kind, name, "rollback", version, author, comment, role)
            return stored.info, item.seq

    def delete(self, kind: str, name: str, *, author: str, role: str = "") -> int:
        with self._lock:
            item = self._items.get((kind, name))
            if item is None or item.deleted or item.current is None:
                raise VersionMissing(kind, name)
            item.current, item.deleted = None, True
            item.seq = self._append(kind, name, "delete", None, author, "", role)
            return item.seq

    def refuse(self, kind: str, name: str, *, author: str, role: str, comment: str) -> int:
        with self._lock:
            return self._append(kind, name, "refused", None, author, comment, role)

    def load(self, kind: str, name: str, version: int) -> Version:
        with self._lock:
            item = self._items.get((kind, name))
            if item is None or not 1 <= int(version) <= len(item.versions):
                raise VersionMissing(kind, name, version)
            found = item.versions[int(version) - 1]
            return Version(found.info, copy.deepcopy(found.payload))

    def versions(self, kind: str, name: str) -> list[VersionInfo]:
        with self._lock:
            item = self._items.get((kind, name))
            return [v.info for v in item.versions] if item else []

    def history(self, kind: str, name: str) -> list[Change]:
        with self._lock:
            return [c for c in self._log if c.kind == kind and c.name == name]

    def changes_since(self, seq: int, limit: int = 1000) -> list[Change]:
        with self._lock:
            return [c for c in self._log if c.seq > seq][:limit]

    def last_seq(self) -> int:
        with self._lock:
            return self._log[-1].seq if self._log else 0

    def wait_for_change(self, after_seq: int, timeout_s: float) -> None:
        with self._lock:
            self._lock.wait_for(lambda: self.last_seq() > after_seq, timeout=timeout_s)

    def _append(self, kind: str, name: str, event: str, version: int | None, author: str, comment: str,
                role: str = "") -> int:
        change = Change(len(self._log) + 1, kind, name, event, version, author, comment, now_iso(), time.time(),
                        self.origin, role)
        self._log.append(change)
        self._lock.notify_all()
        return change.seq
