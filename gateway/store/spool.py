"""A bounded on-disk write buffer (JSONL): what the store keeps while the database is unreachable.

Why on disk: the Information State must lose nothing across a DB outage or a gateway restart, so
pending writes live in a file (Extended JSON, so dates and ObjectIds survive) until they are flushed.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import Any

from bson import json_util


class SpoolFull(RuntimeError):
    """The buffer reached its bound; the write was refused (and counted) instead of growing forever."""


class Spool:
    """Append-only JSONL of (collection, document); drained in order after reconnecting."""

    def __init__(self, path: Path, max_docs: int) -> None:
        self.path = Path(path)
        self.max_docs = max_docs
        self._lock = threading.Lock()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._count = self._count_lines()

    def _count_lines(self) -> int:
        if not self.path.exists():
            return 0
        with open(self.path, "rb") as fh:
            return sum(1 for line in fh if line.strip())

    def __len__(self) -> int:
        return self._count

    def append(self, collection: str, doc: dict[str, Any]) -> None:
        """Append one write durably (flushed + fsync'd), or raise SpoolFull at the bound."""
        line = json_util.dumps({"c": collection, "d": doc}, json_options=json_util.RELAXED_JSON_OPTIONS)
        with self._lock:
            if self._count >= self.max_docs:
                raise SpoolFull(f"write buffer {self.path} is full ({self.max_docs} documents)")
            with open(self.path, "a", encoding="utf-8") as fh:
                fh.write(line + "\n")
                fh.flush()
                os.fsync(fh.fileno())
            self._count += 1

    def read(self) -> list[tuple[str, dict[str, Any]]]:
        """All pending writes, oldest first; a corrupt line (torn write at a crash) is skipped."""
        with self._lock:
            if not self.path.exists():
                return []
            items = []
            with open(self.path, encoding="utf-8") as fh:
                for line in fh:
                    if not line.strip():
                        continue
                    try:
                        entry = json_util.loads(line)
                    except ValueError:
                        continue
                    items.append((entry["c"], entry["d"]))
            return items

    def drop_first(self, n: int) -> None:
        """Forget the first ``n`` writes (they are in the database now); rewrite atomically."""
        with self._lock:
            if not self.path.exists():
                return
            with open(self.path, encoding="utf-8") as fh:
                lines = [line for line in fh if line.strip()]
            rest = lines[n:]
            tmp = self.path.with_suffix(".tmp")
            with open(tmp, "w", encoding="utf-8") as fh:
                fh.writelines(rest)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.path)
            self._count = len(rest)
