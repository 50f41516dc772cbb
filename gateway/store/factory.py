"""Open the Information State the settings ask for: a real MongoDB (MONGO_URI) or the embedded one."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from gateway.store.embedded import EmbeddedMongo, running_owner
from gateway.store.store import InformationState


class ManagedStore(InformationState):
    """An InformationState that also owns the embedded database process it started."""

    embedded: EmbeddedMongo | None = None

    def close(self, flush_timeout_s: float = 5.0) -> None:
        super().close(flush_timeout_s)
        if self.embedded:
            self.embedded.stop()

    def health(self) -> dict[str, Any]:
        out = super().health()
        if self.embedded:
            out["embedded_port"] = self.embedded.port
        return out


def store_uri(settings: Any) -> str | None:
    """The configured MongoDB URI (``MONGO_URI`` wins over ``settings.store.mongo_uri``), if any."""
    return os.environ.get("MONGO_URI") or settings.store.mongo_uri


def embedded_dir(settings: Any) -> Path:
    return Path(settings.data_dir) / "mongo"


def open_store(settings: Any, *, join_running: bool = False) -> ManagedStore:
    """MONGO_URI (env) > settings.store.mongo_uri > a SecantusDB daemon under <data_dir>/mongo.

    ``join_running``: when another live process already runs the embedded database of this data
    dir, use it (tools such as ``printeps export``) instead of failing with EmbeddedDbHeld (a
    second gateway process must be pointed at it explicitly, with MONGO_URI).
    """
    cfg = settings.store
    uri = store_uri(settings)
    embedded = None
    if not uri and join_running:
        owner = running_owner(embedded_dir(settings))
        uri = owner.get("uri") if owner else None
    if not uri:
        embedded = embedded_database(settings)
        uri = embedded.start()
    store = ManagedStore(uri, cfg.database, Path(settings.data_dir) / "store" / "journal",
                         backend="embedded" if embedded else "external", timeout_ms=cfg.timeout_ms,
                         spool_max_docs=cfg.spool_max_docs, retry_interval_s=cfg.retry_interval_s,
                         fsync=cfg.journal_fsync, linger_s=cfg.ship_linger_s,
                         ship_process=cfg.ship_from == "process", retention_days=cfg.retention_days)
    store.embedded = embedded
    store.apply_retention()
    return store


def embedded_database(settings: Any) -> EmbeddedMongo:
    """The embedded SecantusDB of ``settings`` (not started): one place for its options, whether one
    gateway process starts it or ``printeps serve --workers`` starts it for all of them."""
    cfg = settings.store
    return EmbeddedMongo(embedded_dir(settings), cfg.embedded_port, cfg.embedded_cache,
                         oplog_max_entries=cfg.embedded_oplog_max_entries,
                         oplog_retention_s=cfg.embedded_oplog_retention_s)
