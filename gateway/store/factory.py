"""Open the Information State the settings ask for: a real MongoDB (MONGO_URI) or the embedded one."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from gateway.store.embedded import EmbeddedMongo
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


def open_store(settings: Any, *, spool_name: str = "spool.jsonl") -> ManagedStore:
    """MONGO_URI (env) > settings.store.mongo_uri > a SecantusDB daemon under <data_dir>/mongo."""
    cfg = settings.store
    data = Path(settings.data_dir) / "store"
    uri = os.environ.get("MONGO_URI") or cfg.mongo_uri
    embedded = None
    if not uri:
        embedded = EmbeddedMongo(Path(settings.data_dir) / "mongo", cfg.embedded_port, cfg.embedded_cache)
        uri = embedded.start()
    store = ManagedStore(uri, cfg.database, data / spool_name, backend="embedded" if embedded else "external",
                         timeout_ms=cfg.timeout_ms, spool_max_docs=cfg.spool_max_docs,
                         retry_interval_s=cfg.retry_interval_s)
    store.embedded = embedded
    return store
