"""The Information State (MongoDB via pymongo, mongodb_store style). See docs/information-state.md.

    store = open_store(settings)            # MONGO_URI / settings.store.mongo_uri, else embedded SecantusDB
    store.record("actions", {...}, stored_type="printeps/Action", inserted_by="gateway_node")
    store.query("actions", type="printeps/Action", since=dt, filters={"robot": "pepper"})
    store.health()                          # {"status": "ok" | "degraded", "buffered": n, ...}
    store.close()                           # also stops the embedded database it started
"""

from gateway.store.factory import open_store
from gateway.store.store import (
    ACTIONS,
    QUERY_RESULTS,
    RDF_EVENTS,
    RULE_FIRINGS,
    SENSOR_MESSAGES,
    InformationState,
    StoreError,
    StoreUnavailable,
)

__all__ = [
    "ACTIONS", "QUERY_RESULTS", "RDF_EVENTS", "RULE_FIRINGS", "SENSOR_MESSAGES",
    "InformationState", "StoreError", "StoreUnavailable", "open_store",
]
