"""Every serving process follows every change: a thread that reads the catalog's change log.

Why level-triggered: an entry only says *which* item changed; the service that owns the item
(rule sets, workflows, knowledge, queries, mappings) is asked to ``sync(name)`` — to read the head
and converge to it. So an entry seen twice changes nothing, entries arriving out of order cannot
leave a process on an old version, and a periodic full ``reconcile`` repairs anything a crashed
writer left unannounced.

Sequence numbers are claimed before their entry is written, so the log can show a gap for a
moment (a slow writer) or for ever (a writer that died). A gap is waited for up to ``gap_wait_s``
and then passed over; entries past a gap are applied at once either way.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Callable, Protocol

from gateway.base.versions import Catalog, Change

log = logging.getLogger(__name__)


class Follows(Protocol):
    """A service whose items are versioned in the catalog (every one is a
    :class:`gateway.base.lifecycle.CatalogLifecycle`; the protocol keeps the follower testable
    with a stub)."""

    def sync(self, name: str) -> None:
        """Converge ``name`` to the catalog's head (deployed, moved back, or deleted)."""
        ...

    def reconcile(self) -> object:
        """Converge every item of this kind (names no longer in the catalog included); what it
        returns (a report) is not read here."""
        ...


class ChangeFollower:
    """Reads the change log after ``start_seq`` and calls ``services[kind].sync(name)`` per entry."""

    def __init__(self, catalog: Catalog, services: dict[str, Follows], *, start_seq: int,
                 reconcile_interval_s: float = 30.0, gap_wait_s: float = 5.0,
                 on_applied: Callable[[Change], None] | None = None) -> None:
        self.catalog = catalog
        self.services = services
        self.reconcile_interval_s = reconcile_interval_s
        self.gap_wait_s = gap_wait_s
        self.on_applied = on_applied
        self.low_water = start_seq  # every entry <= this has been handled (or given up on)
        self._seen: set[int] = set()
        self._gap_since: dict[int, float] = {}
        self.applied = 0
        self.skipped = 0
        self.errors = 0
        self.last_error: str | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="change-follower", daemon=True)

    def start(self) -> "ChangeFollower":
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=timeout_s)

    def health(self) -> dict[str, object]:
        return {"status": "ok" if self._thread.is_alive() or not self._stop.is_set() else "stopped",
                "seq": self.low_water, "applied": self.applied, "skipped": self.skipped, "errors": self.errors,
                "last_error": self.last_error}

    # ---- the loop --------------------------------------------------------------------------------
    def _run(self) -> None:
        next_reconcile = time.monotonic() + self.reconcile_interval_s
        while not self._stop.is_set():
            try:
                self.catalog.wait_for_change(self.low_water, timeout_s=1.0)
                if self._stop.is_set():
                    return
                self.poll()
                if time.monotonic() >= next_reconcile:
                    self.reconcile()
                    next_reconcile = time.monotonic() + self.reconcile_interval_s
            except Exception as exc:  # the database is away, or a bug: never let the follower die
                self.errors += 1
                self.last_error = f"{type(exc).__name__}: {exc}"
                log.warning("change follower: %s", self.last_error)
                self._stop.wait(1.0)

    def poll(self) -> int:
        """Handle the entries after the low-water mark now; returns how many were applied."""
        applied = 0
        for change in self.catalog.changes_since(self.low_water):
            if change.seq in self._seen:
                continue
            self._seen.add(change.seq)
            if self._apply(change):
                applied += 1
        self._advance()
        return applied

    def _apply(self, change: Change) -> bool:
        service = self.services.get(change.kind)
        if service is None:
            if change.event not in ("malformed", "none"):
                self.skipped += 1
                log.error("change follower: skipped entry %d: unknown kind %r", change.seq, change.kind)
            return False
        if change.event in ("none", "refused"):  # nothing changed (a lost race; a policy refusal)
            return False
        try:
            service.sync(change.name)
        except Exception as exc:  # one bad item must not stop the others from following
            self.errors += 1
            self.last_error = f"{change.kind} {change.name!r}: {type(exc).__name__}: {exc}"
            log.error("change follower: could not apply change %d (%s %s %r): %s", change.seq, change.event,
                      change.kind, change.name, exc)
            return False
        self.applied += 1
        if self.on_applied is not None:
            self.on_applied(change)
        return True

    def _advance(self) -> None:
        """Move the low-water mark over contiguous seen entries and over gaps older than gap_wait_s."""
        now = time.monotonic()
        while True:
            nxt = self.low_water + 1
            if nxt in self._seen:
                self._seen.discard(nxt)
                self._gap_since.pop(nxt, None)
                self.low_water = nxt
                continue
            if not any(s > nxt for s in self._seen):
                return  # nothing seen beyond: not a gap, just the end of the log
            started = self._gap_since.setdefault(nxt, now)
            if now - started < self.gap_wait_s:
                return
            log.warning("change follower: entry %d never appeared; passing over it", nxt)
            self._gap_since.pop(nxt, None)
            self.low_water = nxt

    def reconcile(self) -> None:
        """Ask every service to converge all its items (catches what a crashed writer never logged)."""
        for kind, service in self.services.items():
            try:
                service.reconcile()
            except Exception as exc:
                self.errors += 1
                self.last_error = f"reconcile {kind}: {type(exc).__name__}: {exc}"
                log.error("change follower: %s", self.last_error)
