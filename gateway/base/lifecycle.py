"""The one life cycle of everything versioned in the catalog: seed, load, follow, serve or drop.

Why one: rule sets (:class:`gateway.engine.Engine`), workflows, the knowledge, continuous queries
and mappings are five different things to serve, but the way a process keeps serving the right
version of them is the same, and it is where multi-process bugs hide. So it is written once here:

- **head → load → serve/drop.** :meth:`CatalogLifecycle.sync` reads an item's head; a deleted or
  unknown item is dropped, a version already served is left alone, any other current version is
  loaded from the catalog and handed to the service to serve (:meth:`~CatalogLifecycle._apply`).
  Each served version remembers the sequence number of the catalog change behind it, and only a
  newer change replaces it (a deploy answered here and the follower's sync of the same deploy
  may race: the later change wins, see :class:`gateway.base.versions.Served`).
- **load** (at start) serves every live item, **reconcile** (the change follower's periodic
  safety net, :mod:`gateway.runtime.follower`) converges every item known here or in the catalog.
  A stored item that no longer loads is logged and reported, and the others are still served.
- **seed(folder)** imports the files of a folder that the catalog has never had as version 1
  (author "seed"); the folder only ever fills an empty store: an item the catalog has (even
  deleted) is never overwritten by files, and two processes seeding at once store it once.
  Every service returns the same report, ``{item: "seeded v1" | "kept v3" | "kept (deleted)" |
  "kept (seeded by another process)" | "skipped: …" | "failed: …"}``.

A service says only what is specific to it: its catalog ``kind``, how it serves and drops one
version, which files of a seed folder are items and how one is read and stored. Plain Python, no
JVM, no database: the catalog is the :class:`gateway.base.versions.Catalog` protocol.
"""

from __future__ import annotations

import logging
import threading
from pathlib import Path
from typing import Any, ClassVar, Iterable

from gateway.base.versions import Catalog, CatalogConflict, Head, MemoryCatalog, Served, Version

log = logging.getLogger(__name__)

NEVER_SEQ = 1 << 62
"""The sequence number a drop uses when the catalog has no head for the item at all: nothing
served can be newer, so whatever is served goes."""


class NotAnItem(Exception):
    """A path of a seed folder that holds no item (e.g. a rule folder without rule files)."""


class CatalogLifecycle:
    """The shared life cycle of a catalog-backed service (see the module docstring).

    Subclasses set :attr:`kind`, :attr:`failures` and :attr:`seed_races`, and implement
    :meth:`_apply`, :meth:`_withdraw` and the three seed hooks. What is served is kept in
    :attr:`_served` unless a subclass keeps it itself (then it overrides :meth:`served` and
    :meth:`served_names`).
    """

    kind: ClassVar[str]
    failures: ClassVar[tuple[type[Exception], ...]] = ()
    """What a stored version or a seed file that is wrong raises: logged, reported and skipped."""
    seed_races: ClassVar[tuple[type[Exception], ...]] = (CatalogConflict,)
    """What storing a seed raises when another process stored the same item first."""

    def __init__(self, catalog: Catalog | None = None) -> None:
        self.catalog: Catalog = catalog if catalog is not None else MemoryCatalog()
        self._served = Served()
        self._lock = threading.RLock()

    # ---- what is served here --------------------------------------------------------------------
    def served(self, name: str) -> tuple[int, int] | None:
        """``(version, seq)`` of what this process serves of ``name`` (None: nothing)."""
        return self._served.get(name)

    def served_names(self) -> Iterable[str]:
        return self._served.names()

    def is_serving(self, name: str, head: Head) -> bool:
        """Already serving what ``head`` points at (that change or a newer one)."""
        served = self.served(name)
        return served is not None and served[0] == head.current and served[1] >= head.seq

    # ---- following the catalog ------------------------------------------------------------------
    def sync(self, name: str) -> None:
        """Converge ``name`` to the catalog's head: serve its current version, or drop it when it
        was deleted (what the change follower calls for every change of this kind)."""
        self._converge(name, self.catalog.head(self.kind, name), elsewhere=True)

    def reconcile(self) -> dict[str, str]:
        """Converge every item known here or in the catalog; ``{name: "serving vN" | "failed: …"}``."""
        names = {h.name for h in self.catalog.heads(self.kind)} | set(self.served_names())
        return self._converge_all(sorted(names), elsewhere=True)

    def load(self) -> dict[str, str]:
        """Serve every live item of the catalog now (at start: serve at once, not on first use)."""
        return self._converge_all(sorted(h.name for h in self.catalog.heads(self.kind) if h.live), elsewhere=False)

    def _converge(self, name: str, head: Head | None, *, elsewhere: bool) -> None:
        if head is None or not head.live:
            self._withdraw(name, head.seq if head is not None else NEVER_SEQ)
            return
        if self.is_serving(name, head):
            return
        self._apply(name, self.catalog.load(self.kind, name, head.current), head.seq,  # type: ignore[arg-type]
                    elsewhere=elsewhere)

    def _converge_all(self, names: list[str], *, elsewhere: bool) -> dict[str, str]:
        report: dict[str, str] = {}
        stale: list[tuple[Version, int]] = []
        for name in names:
            head = self.catalog.head(self.kind, name)
            if head is None or not head.live:
                self._withdraw(name, head.seq if head is not None else NEVER_SEQ)
            elif self.is_serving(name, head):
                report[name] = f"serving v{head.current}"
            else:
                stale.append((self.catalog.load(self.kind, name, head.current), head.seq))  # type: ignore[arg-type]
        report.update(self._apply_all(stale, elsewhere=elsewhere))
        return report

    def _apply_all(self, stale: list[tuple[Version, int]], *, elsewhere: bool) -> dict[str, str]:
        """Serve each loaded version; one that fails is logged and reported, the others go on.
        A service that derives something from all its items at once may apply them together."""
        report: dict[str, str] = {}
        for stored, seq in stale:
            name = stored.info.name
            try:
                self._apply(name, stored, seq, elsewhere=elsewhere)
                report[name] = f"serving v{stored.info.version}"
            except self.failures as exc:
                log.error("%s %s v%d not served: %s", self.kind, name, stored.info.version, exc)
                report[name] = f"failed: {exc}"
        return report

    def _apply(self, name: str, stored: Version, seq: int, *, elsewhere: bool) -> None:
        """Serve ``stored`` (from catalog change ``seq``) unless a newer change is served already.
        ``elsewhere``: the change came from the catalog (another process, or a missed change),
        not from loading at start."""
        raise NotImplementedError

    def _withdraw(self, name: str, seq: int) -> None:
        """Stop serving ``name`` (deleted by change ``seq``) unless a newer change is served."""
        raise NotImplementedError

    # ---- the seed folder ------------------------------------------------------------------------
    def seed(self, folder: str | Path | None) -> dict[str, str]:
        """Store the items of ``folder`` the catalog has never had as version 1 (author "seed");
        None or a missing folder seeds nothing. Returns the report of the module docstring, by
        item name (by file name for a file that names no item)."""
        report: dict[str, str] = {}
        if not folder:
            return report
        root = Path(folder)
        if not root.is_dir():
            log.warning("%s seed folder %s does not exist", self.kind, root)
            return report
        for path in self._seed_paths(root):
            try:
                name, item = self._read_seed(path)
            except NotAnItem as skipped:
                report[path.name] = f"skipped: {skipped}"
                continue
            except self.failures as exc:
                log.error("%s seed %s not imported: %s", self.kind, path, exc)
                report[path.name] = f"failed: {exc}"
                continue
            report[name] = self._seed_item(name, item, path)
        return report

    def _seed_item(self, name: str, item: Any, path: Path) -> str:
        head = self.catalog.head(self.kind, name)
        if head is not None:
            return f"kept v{head.current}" if head.live else "kept (deleted)"
        try:
            return f"seeded v{self._store_seed(name, item, path)}"
        except self.seed_races:
            return "kept (seeded by another process)"
        except self.failures as exc:
            log.error("%s seed %s not imported: %s", self.kind, path, exc)
            return f"failed: {exc}"

    def _seed_paths(self, folder: Path) -> list[Path]:
        """The files (or folders) of a seed folder that hold one item each, in a stable order."""
        raise NotImplementedError

    def _read_seed(self, path: Path) -> tuple[str, Any]:
        """The item's name and what :meth:`_store_seed` needs (raises one of :attr:`failures`, or
        :class:`NotAnItem`). A service whose names are the file names may read the file later,
        in :meth:`_store_seed`, so that a kept item's file is never read."""
        raise NotImplementedError

    def _store_seed(self, name: str, item: Any, path: Path) -> int:
        """Check and store a seed as the first version of ``name`` (``base_version=0``, so a
        race with another process raises one of :attr:`seed_races`); returns its number."""
        raise NotImplementedError

    def _save_seed(self, name: str, payload: Any, hash: str, path: Path) -> int:
        """Store ``payload`` as version 1 of ``name``, seeded from ``path``."""
        info, _ = self.catalog.save(self.kind, name, payload, author="seed", comment=f"seeded from {path.name}",
                                    hash=hash, base_version=0)
        return info.version
