"""Compiled rule units shared through the Information State, for gateways on several hosts.

Why: the unit cache on disk (:mod:`gateway.engine.unit_cache`) is shared by the processes of one
host only. Gateways on other hosts follow every deploy; without this each of them compiled the
new version itself — minutes for a 10,000-rule set, on every host, after every cold start. Here
the process that compiles a unit also keeps its class bytes in MongoDB (``rule_units``), and the
assembly plan of every set that compiled (``rule_plans``), before the deploy is announced; a
follower on another host then assembles the version from them instead of compiling.

Documents are keyed by the unit cache's environment (Drools version, helper classes, format) and
the content hash, so classes made by another Drools are never used. A unit too big for one
document (MongoDB's 16 MB) stays local. Entries not used for ``ttl_days`` are removed by a TTL
index. Failures here never fail a build: the unit is compiled (or kept) locally instead.
"""

from __future__ import annotations

import logging
from datetime import datetime, timezone
from typing import Any

from bson import Binary
from pymongo.errors import PyMongoError

log = logging.getLogger(__name__)

UNITS = "rule_units"
PLANS = "rule_plans"
MAX_DOC_BYTES = 15 * 1024 * 1024  # below MongoDB's 16 MB document limit, with room for the manifest


class SharedUnitStore:
    """The shared tier of the unit cache (see ``UnitCache.shared``): units and plans by id."""

    def __init__(self, db: Any, ttl_days: float = 30.0) -> None:
        self.db = db
        self.ttl_s = int(ttl_days * 86400)
        self._indexed = False

    def _index(self) -> None:
        if self._indexed:
            return
        self._indexed = True
        for name in (UNITS, PLANS):
            try:
                self.db[name].create_index("used_at", expireAfterSeconds=self.ttl_s)
            except PyMongoError as exc:  # an optimisation: entries then just stay
                log.warning("%s: TTL index not created: %s", name, exc)

    # ---- units -----------------------------------------------------------------------------------
    def get_unit(self, env: str, unit_id: str) -> tuple[dict[str, Any], bytes] | None:
        """(manifest, class bytes) of a unit another process compiled, or None."""
        doc = self._find(UNITS, f"{env}/{unit_id}")
        if doc is None:
            return None
        return doc["manifest"], bytes(doc["data"])

    def put_unit(self, env: str, manifest: dict[str, Any], data: bytes) -> None:
        if len(data) > MAX_DOC_BYTES:
            log.info("rule unit %s (%d bytes) is too big to share; kept on this host", manifest["id"], len(data))
            return
        self._put(UNITS, f"{env}/{manifest['id']}", {"manifest": manifest, "data": Binary(data), "size": len(data)})

    # ---- plans -----------------------------------------------------------------------------------
    def get_plan(self, env: str, content_hash: str) -> dict[str, Any] | None:
        doc = self._find(PLANS, f"{env}/{content_hash}")
        return None if doc is None else doc["plan"]

    def put_plan(self, env: str, content_hash: str, plan: dict[str, Any]) -> None:
        self._put(PLANS, f"{env}/{content_hash}", {"plan": plan})

    # ---- plumbing --------------------------------------------------------------------------------
    def _find(self, collection: str, key: str) -> dict[str, Any] | None:
        self._index()
        try:
            doc = self.db[collection].find_one_and_update({"_id": key}, {"$set": {"used_at": _now()}})
        except PyMongoError as exc:
            log.warning("shared rule units unreachable (%s); compiling locally", exc)
            return None
        return doc

    def _put(self, collection: str, key: str, fields: dict[str, Any]) -> None:
        self._index()
        try:
            self.db[collection].update_one({"_id": key}, {"$set": {**fields, "used_at": _now()}}, upsert=True)
        except PyMongoError as exc:
            log.warning("could not share %s %s: %s", collection, key, exc)


def _now() -> datetime:
    return datetime.now(timezone.utc)
