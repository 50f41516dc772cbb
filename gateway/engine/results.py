"""What a fire returns, and the translation of the Java Runner's JSON answer into it."""

from __future__ import annotations

import enum
import json
import math
import uuid
from dataclasses import dataclass, field
from typing import Any

import orjson

from gateway.engine.errors import FactError, FireTimeout, RuleRuntimeError, RunawayRules


# The JVM boundary's shared settings for stateful sessions and their feeds:
BUFFER_BYTES = 64 * 1024  # each direct buffer shared with the Java side (bigger inputs/answers take a String path)
NO_TIMESTAMP = -(2**63)  # Java's Long.MIN_VALUE: "do not move the clock"


@dataclass(slots=True)
class FireResult:
    """The outcome of one fire: actions requested by then-parts (in order), rules fired with the
    facts they matched, and the facts in the session afterwards."""

    ruleset: str
    version: int
    actions: list[dict[str, Any]]
    fired: list[dict[str, Any]]
    facts: list[dict[str, Any]] = field(default_factory=list)
    fire_count: int = 0
    duration_ms: float = 0.0
    decision_id: str | None = None  # set when the fire is a decision (recorded), not for drafts

    def to_dict(self) -> dict[str, Any]:
        out = {
            "ruleset": self.ruleset,
            "version": self.version,
            "actions": self.actions,
            "fired": self.fired,
            "facts": self.facts,
            "fire_count": self.fire_count,
            "duration_ms": round(self.duration_ms, 3),
        }
        if self.decision_id is not None:
            out["decision_id"] = self.decision_id
        return out


@dataclass(frozen=True, slots=True)
class PreparedFire:
    """A stateless fire ready for the Java ``Runner.fire`` call: what the engine decided before it
    (the version, the encoded facts, the limits) and needs after it to read the answer."""

    name: str
    version: int
    runner: Any  # the rule set's Java Runner
    facts_json: str
    limit: int
    return_facts: bool
    record_facts: bool


def _uuid_or_enum(value: Any) -> Any:
    """What orjson writes for a UUID (its text) and an Enum (its value), and the strict encoder
    therefore must write too: the same fact must not be accepted or refused by which path it took."""
    if isinstance(value, uuid.UUID):
        return str(value)
    if isinstance(value, enum.Enum):
        return value.value
    raise TypeError(f"Object of type {type(value).__name__} is not JSON serializable")


# The strict encoder: what JSON allows, nothing else. Built once (streams encode per event).
_STRICT = json.JSONEncoder(allow_nan=False, separators=(",", ":"), default=_uuid_or_enum)
# orjson is ~8x faster; these options make it refuse (TypeError) what the strict encoder refuses
# instead of quietly writing datetimes and dataclasses as strings and objects.
_ORJSON_OPTIONS = orjson.OPT_PASSTHROUGH_DATETIME | orjson.OPT_PASSTHROUGH_DATACLASS


def encode_facts_bytes(facts: Any, max_facts: int) -> bytes:
    """Facts -> the UTF-8 JSON the Java side reads. Refuses what JSON cannot carry, naming the fact.

    Why two encoders: orjson is the fast path; it writes NaN and infinity as ``null`` and refuses
    non-string keys and huge integers, so any output with a ``null`` in it and any refusal is redone
    by the strict standard encoder, whose answer (or error) is the one that counts. Both write a
    UUID as its text and an Enum as its value.
    """
    if not isinstance(facts, (list, tuple)):
        raise FactError([{"index": -1, "type": None, "id": None, "field": None,
                          "message": f"facts must be a list of objects, got {type(facts).__name__}"}])
    if len(facts) > max_facts:
        raise FactError([{"index": -1, "type": None, "id": None, "field": None,
                          "message": f"too many facts: {len(facts)} (at most {max_facts})"}])
    try:
        data = orjson.dumps(facts, option=_ORJSON_OPTIONS)
        if b"null" not in data:
            return data
    except TypeError:  # orjson.JSONEncodeError is a TypeError
        pass
    return _strict(facts).encode("utf-8")


def encode_facts(facts: Any, max_facts: int) -> str:
    """:func:`encode_facts_bytes` as a str (for the Java calls that take a String)."""
    return encode_facts_bytes(facts, max_facts).decode("utf-8")


def _strict(facts: Any) -> str:
    try:
        return _STRICT.encode(facts)
    except (ValueError, TypeError, RecursionError) as exc:
        raise FactError([_locate_unencodable(facts, exc)]) from None


def _locate_unencodable(facts: Any, exc: Exception) -> dict[str, Any]:
    for index, fact in enumerate(facts):
        if not isinstance(fact, dict):
            continue
        for key, value in fact.items():
            if not isinstance(key, (str, int, float, bool)) and key is not None:
                return {"index": index, "type": fact.get("type"), "id": fact.get("id"), "field": repr(key),
                        "message": f"field name {key!r}: a {type(key).__name__} is not a JSON object key"}
            try:
                json.dumps(value, allow_nan=False, default=_uuid_or_enum)
            except RecursionError:
                return {"index": index, "type": fact.get("type"), "id": fact.get("id"), "field": str(key),
                        "message": f"field '{key}': a {type(value).__name__} nested too deeply to encode as JSON"}
            except (ValueError, TypeError):
                bad = "NaN or infinity" if isinstance(value, float) and not math.isfinite(value) else type(value).__name__
                return {"index": index, "type": fact.get("type"), "id": fact.get("id"), "field": str(key),
                        "message": f"field '{key}': {bad} is not a JSON value"}
    return {"index": -1, "type": None, "id": None, "field": None, "message": f"facts are not JSON: {exc}"}


_NOTHING_FIRED = '{"ok":true,"fireCount":0,"actions":[],"fired":[]}'
_NOTHING_FIRED_BYTES = _NOTHING_FIRED.encode()


def decode_result(answer: str | bytes | bytearray, ruleset: str, version: int, duration_ms: float) -> FireResult:
    """Parses the Runner's answer (text, or UTF-8 bytes from a session's buffer); refusals and
    runaways become exceptions. Kept lean: streams decode one answer per event."""
    if answer == _NOTHING_FIRED or answer == _NOTHING_FIRED_BYTES:  # the common case on a stream: skip the JSON parse
        return FireResult(ruleset, version, [], [], [], 0, duration_ms)
    return result_of(orjson.loads(answer), ruleset, version, duration_ms)  # orjson: ~3x faster than json.loads


def finished(prepared: PreparedFire, answer: dict[str, Any], duration_ms: float) -> FireResult:
    """The result of ``prepared``'s fire (Engine.prepare_fire) from the Runner's parsed ``answer``."""
    return result_of(answer, prepared.name, prepared.version, duration_ms)


def result_of(data: dict[str, Any], ruleset: str, version: int, duration_ms: float) -> FireResult:
    """The FireResult of the Runner's parsed answer ``data``; refusals and runaways raise."""
    if data.get("ok") is not True:
        raise_refusal(data, ruleset)
    return FireResult(ruleset, version, data["actions"], fired_of(data), data.get("facts", []), data["fireCount"], duration_ms)


def fired_of(data: dict[str, Any]) -> list[dict[str, Any]]:
    """The answer's firings, each with its facts. A request-join fire (whose facts cannot change)
    sends each matched fact once, in ``factTable``, and each firing its facts' numbers: each
    firing gets its own copy of each fact here, as if written at every firing (Recorder.java)."""
    fired = data["fired"]
    table = data.get("factTable")
    if table is not None:
        for firing in fired:
            firing["facts"] = [dict(table[k]) if isinstance(table[k], dict) else table[k] for k in firing["facts"]]
    return fired


def raise_refusal(data: dict[str, Any], ruleset: str | None = None) -> None:
    """Raises the error a Java answer with ``"ok": false`` reports (``ruleset``: whose fire it was)."""
    kind = data.get("kind")
    if kind == "timeout":
        raise FireTimeout(ruleset, int(data.get("limit_ms", 0)) / 1000, int(data.get("fired", 0)))
    if kind == "facts":
        raise FactError(data.get("errors", []), data.get("errorCount"))
    if kind == "runaway":
        raise RunawayRules(int(data.get("limit", 0)), data.get("counts", {}))
    raise RuleRuntimeError(data.get("rule"), data.get("message", "unknown error"))
