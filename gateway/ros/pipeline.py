"""The gateway's processing chain, in plain Python with every stage injected:

    Entrance reading → validate → stream/detector (RDF stream + registered queries) → detection
    events → facts → business rules → then-part actions → dispatcher (robot services)

and everything it sees or does recorded in the Information State: sensor messages, RDF stream
items, query results, rule firings (rules, facts, version) and actions with outcomes.
Why plain: the ROS node only feeds it messages; tests drive it directly and with real nodes.
"""

from __future__ import annotations

import logging
import time
from typing import Any, Callable, Protocol

from gateway.ros.detector import EventDetector
from gateway.ros.readings import ReadingError, validate_entrance
from gateway.store.store import QUERY_RESULTS, RDF_EVENTS, RULE_FIRINGS, SENSOR_MESSAGES

log = logging.getLogger(__name__)

BY = "gateway_node"


class Rules(Protocol):
    def __call__(self, ruleset: str, facts: list[dict[str, Any]]) -> dict[str, Any]:
        """Fire ``ruleset`` over ``facts``; returns a FireResult dict (actions, fired, version, …)."""
        ...


class Dispatcher(Protocol):
    def dispatch(self, action: dict[str, Any], context: dict[str, Any] | None = None) -> dict[str, Any]: ...


def engine_rules(engine: Any) -> Rules:
    """Adapt gateway.engine.Engine to the Rules stage."""

    def fire(ruleset: str, facts: list[dict[str, Any]]) -> dict[str, Any]:
        # origin "ros": the pipeline records this firing in the Information State itself
        return engine.fire(ruleset, facts, context={"origin": "ros"}).to_dict()

    return fire


class Pipeline:
    """One instance per gateway node; ``on_reading`` is called from a single worker thread."""

    def __init__(self, detector: EventDetector, rules: Rules, dispatcher: Dispatcher, store: Any, *,
                 ruleset: str = "reception", robot_positions: dict[str, str] | None = None,
                 max_customers: int = 100, max_distance_m: float = 20.0, forget_after_s: float = 30.0,
                 on_event: Callable[[str, dict[str, Any]], None] | None = None) -> None:
        self.detector = detector
        self.rules = rules
        self.dispatcher = dispatcher
        if hasattr(dispatcher, "record"):
            dispatcher.record = self._record
        self.store = store
        self.ruleset = ruleset
        self.positions = dict(robot_positions or {})
        self.max_customers = max_customers
        self.max_distance_m = max_distance_m
        self.forget_after_s = forget_after_s
        self.on_event = on_event or (lambda kind, payload: None)
        self.handled: dict[str, float] = {}  # customer id → stamp it was last part of a detection
        self._pending: list[tuple[str, dict[str, Any], str]] = []
        self.stats = {"readings": 0, "rejected": 0, "detections": 0, "firings": 0, "actions": 0, "failed": 0}

    def _record(self, collection: str, doc: dict[str, Any], stored_type: str) -> None:
        """Queue a record; written when the reading is done, so the robot is not kept waiting on the DB."""
        if self.store is not None:
            self._pending.append((collection, doc, stored_type))

    def _write_pending(self) -> None:
        pending, self._pending = self._pending, []
        for collection, doc, stored_type in pending:
            self.store.record(collection, doc, stored_type=stored_type, inserted_by=BY)

    def on_reading(self, reading: dict[str, Any], source: str = "entrance") -> list[dict[str, Any]]:
        """Process one Entrance reading; returns the action outcomes it caused (often none).

        Its records (message, stream item, query results, firing) are written right after it is
        processed, in order; action outcomes are written by the dispatcher as they happen.
        """
        try:
            return self._process(reading, source)
        finally:
            self._write_pending()

    def _process(self, reading: dict[str, Any], source: str) -> list[dict[str, Any]]:
        received = time.time()
        try:
            validate_entrance(reading, max_customers=self.max_customers, max_distance_m=self.max_distance_m)
        except ReadingError as exc:
            self.stats["rejected"] += 1
            log.error("rejected reading %r from %s: %s", reading.get("id"), source, exc)
            self._record(SENSOR_MESSAGES, {"source": source, "reading": reading, "error": exc.to_dict()},
                         "printeps/RejectedEntrance")
            self.on_event("rejected", {"source": source, "error": str(exc)})
            return []
        self.stats["readings"] += 1
        if not reading.get("stamp"):
            reading["stamp"] = received
        self._record(SENSOR_MESSAGES, {"source": source, "reading": reading}, "printeps_interfaces/Entrance")
        events = self.detector.push(reading)
        self._record(RDF_EVENTS, {"stream": "http://printeps.org/cafe/entrance", "stamp": reading["stamp"],
                                  "triples": getattr(self.detector, "last_rdf", None),
                                  "items": [{"s": c["id"], "distance": c["distance"]}
                                            for c in reading.get("customers", [])]}, "printeps/RdfStreamItem")
        if not events:
            return []
        for event in events:
            self._record(QUERY_RESULTS, event, f"printeps/QueryResult/{event.get('query', 'query')}")
        return self._on_detection(reading, events)

    def _on_detection(self, reading: dict[str, Any], events: list[dict[str, Any]]) -> list[dict[str, Any]]:
        now = float(reading["stamp"])
        self.handled = {k: t for k, t in self.handled.items() if now - t < self.forget_after_s}
        new_ids = [e["s"] for e in events if e["s"] not in self.handled]
        for e in events:
            self.handled[e["s"]] = now
        if not new_ids:
            return []
        self.stats["detections"] += 1
        facts = self.facts_for(reading, new_ids)
        self.on_event("detected", {"customers": new_ids, "stamp": now})
        started = time.perf_counter()
        try:
            result = self.rules(self.ruleset, facts)
        except Exception as exc:  # the engine's own errors carry what/where; keep them with the facts
            log.error("firing %s failed: %s", self.ruleset, exc)
            self._record(RULE_FIRINGS, {"ruleset": self.ruleset, "facts": facts, "error": str(exc)},
                         "printeps/RuleFiring/error")
            return []
        self.stats["firings"] += 1
        self._record(RULE_FIRINGS, {"ruleset": self.ruleset, "version": result.get("version"), "facts": facts,
                                    "fired": result.get("fired", []), "actions": result.get("actions", []),
                                    "duration_ms": round((time.perf_counter() - started) * 1000, 3),
                                    "customers": new_ids}, "printeps/RuleFiring")
        self.on_event("fired", {"ruleset": self.ruleset, "version": result.get("version"),
                                "rules": [f.get("rule") for f in result.get("fired", [])]})
        outcomes = []
        for action in result.get("actions", []):
            outcome = self.dispatcher.dispatch(action, {"customers": new_ids, "reading": reading.get("id")})
            outcomes.append(outcome)
            self.stats["actions"] += 1
            if outcome["status"] != "ok":
                self.stats["failed"] += 1
            elif action.get("module") == "move":
                params = action.get("params") or {}
                self.positions[params.get("robot")] = params.get("location")
        return outcomes

    def facts_for(self, reading: dict[str, Any], ids: list[str]) -> list[dict[str, Any]]:
        """The reception rules' facts: the party at the entrance, its customers and the robots."""
        entrance = reading.get("location") or "entrance"
        by_id = {c["id"]: c for c in reading.get("customers", [])}
        facts: list[dict[str, Any]] = [{"type": "Entrance", "id": entrance, "number_of_customers": len(ids)}]
        for cid in ids:
            c = by_id.get(cid, {"id": cid})
            facts.append({"type": "Customer", "id": cid, "entrance": entrance, "age": int(c.get("age", -1)),
                          "gender": c.get("gender") or "unknown", "distance": float(c.get("distance", 0.0))})
        for robot, position in self.positions.items():
            facts.append({"type": "Robot", "id": robot, "position": position})
        return facts
