"""KIE Server's batch JSON ↔ the session commands of :mod:`gateway.engine.session`.

The command list and JSON names are KIE's own: ``BatchExecutionCommandImpl``'s ``@XmlElements``
(``insert``, ``insert-elements``, ``fire-all-rules``, ``get-objects``, ``get-object``, ``retract``,
``modify``, ``update``, ``set-global``, ``get-global``, ``query``, ``set-focus``, ``clear-agenda``,
``clear-agenda-group``, ``clear-activation-group``, ``clear-ruleflow-group``, ``get-fact-handles``,
``dispose``, ``fire-until-halt``, the process and work-item commands) plus the two time commands
KIE Server's marshallers register (``advance-session-time``, ``get-session-time``). Field names
follow each command class's ``@XmlAttribute``/``@XmlElement`` names, with the leniencies real
clients and KIE's documentation rely on: ``{"fire-all-rules": ""}``, ``delete`` for ``retract``,
``outIdentifier`` for ``out-identifier``, a fact handle as its external-form text or as the
``{"org.drools.core.common.DefaultFactHandle": {"external-form": …}}`` object KIE returns, a single
setter object instead of a list, ``containedObject``/``@class`` elements in ``insert-elements``.

What comes back is keyed as KIE Server returns it (``results`` and ``facts`` lists of
``{"key", "value"}``), objects as ``{"<package>.<Type>": {fields}}``, handles as
``{"org.drools.core.common.DefaultFactHandle": {"external-form": "0:id:…"}}``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

FACT_HANDLE = "org.drools.core.common.DefaultFactHandle"
FLAT_QUERY_RESULTS = "org.drools.core.runtime.rule.impl.FlatQueryResults"
DISCONNECTED_HANDLE = "org.drools.core.common.DisconnectedFactHandle"
PROCESS_COMMANDS = ("start-process", "signal-event", "complete-work-item", "abort-work-item", "abort-process-instance",
                    "create-process-instance", "start-process-instance", "get-process-instance", "get-work-item")
TIME_UNITS_MS = {"NANOSECONDS": 1e-6, "MICROSECONDS": 1e-3, "MILLISECONDS": 1, "SECONDS": 1000, "MINUTES": 60_000,
                 "HOURS": 3_600_000, "DAYS": 86_400_000}
STRING_OUT_IDENTIFIER = ("fire-all-rules", "get-session-time")  # FireAllRulesCommand(String), GetSessionTimeCommand(String)
NO_ARGUMENTS = ("fire-all-rules", "dispose", "get-objects", "clear-agenda", "get-session-time", "get-fact-handles")


class BatchError(Exception):
    """The batch cannot be read: which command and why (nothing has run)."""

    def __init__(self, message: str, index: int = -1, name: str | None = None) -> None:
        where = f"command {index}" + (f" ({name})" if name else "") + ": " if index >= 0 else ""
        super().__init__(where + message)
        self.index = index
        self.name = name


@dataclass
class Step:
    """One KIE command, translated: its session command (None: answered here) and how to report it."""

    index: int
    name: str
    command: dict[str, Any] | None
    out: str | None = None
    value_key: str | None = None   # results key for the value (KIE puts some only with an out-identifier)
    fact_key: str | None = None    # facts key for the handle(s)
    many: bool = False             # insert-elements: a list of objects / handles


@dataclass
class Batch:
    lookup: str | None
    steps: list[Step] = field(default_factory=list)
    types: list[str] = field(default_factory=list)  # fully qualified names the client used, by simple name

    @property
    def commands(self) -> list[dict[str, Any]]:
        return [s.command for s in self.steps if s.command is not None]

    @property
    def fires(self) -> bool:
        return any(s.command and s.command["op"] == "fire" for s in self.steps)

    def inserted_facts(self) -> list[dict[str, Any]]:
        return [f for s in self.steps if s.command and s.command["op"] == "insert" for f in s.command["facts"]]


def parse_batch(body: Any) -> Batch:
    """A KIE batch (``{"lookup", "commands": [...]}``, or one bare command) as session commands."""
    if not isinstance(body, dict):
        raise BatchError("Bad request, the body must be a JSON object with 'commands'")
    lookup = body.get("lookup")
    if lookup is not None and not isinstance(lookup, str):
        raise BatchError("'lookup' must be a session name (a string) or null")
    if "commands" in body:
        raw = body["commands"]
    elif len(body) == 1 or (len(body) == 2 and "lookup" in body):
        raw = [{k: v for k, v in body.items() if k != "lookup"}]  # KIE also takes one command without a batch
    else:
        raise BatchError("Bad request, no commands to be executed - either wrong format or no data")
    if not isinstance(raw, list) or not raw:
        raise BatchError("Bad request, no commands to be executed - either wrong format or no data")
    batch = Batch(lookup or None)
    for index, cmd in enumerate(raw):
        if not isinstance(cmd, dict) or len(cmd) != 1:
            raise BatchError("expected an object with exactly one command name, such as {\"insert\": {...}}", index)
        name, args = next(iter(cmd.items()))
        batch.steps.append(_step(index, name, args))
    return batch


def _args(index: int, name: str, args: Any) -> dict[str, Any]:
    if args is None or args == "":
        return {}
    if not isinstance(args, dict):
        raise BatchError(f"its arguments must be an object (or \"\" where there are none), got {type(args).__name__}", index, name)
    return args


def _out(args: dict[str, Any], default: str | None = None) -> str | None:
    for key in ("out-identifier", "outIdentifier", "out_identifier"):
        value = args.get(key)
        if value is not None:
            return str(value)
    return default


def _step(index: int, name: str, raw: Any) -> Step:
    if name in PROCESS_COMMANDS:
        raise BatchError(f"processes are not supported: this gateway runs rules only (KIE Server's BPM capability); "
                         f"'{name}' cannot run here", index, name)
    if name in ("fire-until-halt", "halt"):
        raise BatchError("fire-until-halt would hold the session until halted: send fire-all-rules", index, name)
    if name == "apply-pmml-model-command":
        raise BatchError("PMML models are not supported", index, name)
    if isinstance(raw, str) and name in STRING_OUT_IDENTIFIER:
        # KIE Server's JSON reader builds these with their one-String constructor: the text is the
        # out-identifier, "" too (a real KIE Server answers {"fire-all-rules": ""} under the key "")
        args, out = {}, raw
    else:
        args = _args(index, name, raw)
        out = _out(args)
    if name == "insert":
        fact = fact_from_kie(_required(args, "object", index, name), index, name)
        ret = args.get("return-object", args.get("returnObject", True)) is not False
        command = {"op": "insert", "facts": [fact], "ep": _entry_point(args), "out": out, "ret": ret}
        return Step(index, name, command, out, out if ret and out else None, out)
    if name == "insert-elements":
        objects = args.get("objects", args.get("list"))
        if not isinstance(objects, list):
            raise BatchError("'objects' must be a list of objects", index, name)
        facts = [fact_from_kie(o, index, name, k) for k, o in enumerate(objects)]
        ret = args.get("return-objects", args.get("return-object", True)) is not False
        command = {"op": "insert", "facts": facts, "ep": _entry_point(args), "out": out, "ret": ret, "many": True}
        return Step(index, name, command, out, out if ret and out else None, out, many=True)
    if name == "fire-all-rules":
        if args.get("agendaFilter", args.get("agenda-filter")) is not None:
            raise BatchError("agenda filters are not supported: put the rules in an agenda group and send set-focus", index, name)
        return Step(index, name, {"op": "fire", "max": _int(args.get("max", -1), index, name, "max"), "out": out}, out, out)
    if name == "get-objects":
        # KieSession.getObjects() reads the default entry point's object store only
        return Step(index, name, {"op": "get_objects", "type": _class_filter(args, index, name), "ep": "DEFAULT", "out": out},
                    out, out)
    if name == "get-object":
        return Step(index, name, {"op": "get_object", "handle": fact_handle_text(args, index, name), "out": out}, out, out)
    if name in ("retract", "delete"):
        return Step(index, name, {"op": "delete", "handle": fact_handle_text(args, index, name)})
    if name == "modify":
        # KIE's ModifyCommand sets the fields, then update(handle, object) with no property names:
        # every rule on the type is re-evaluated, as after a whole-fact update
        command = {"op": "modify", "handle": fact_handle_text(args, index, name), "set": _setters(args, index, name),
                   "whole": True}
        return Step(index, name, command)
    if name == "update":
        fact = fact_from_kie(_required(args, "object", index, name), index, name)
        return Step(index, name, {"op": "update", "handle": fact_handle_text(args, index, name), "fact": fact})
    if name == "set-global":
        value = unwrap_typed(args.get("object"))
        command = {"op": "set_global", "name": _required_text(args, "identifier", index, name), "value": value, "out": out}
        return Step(index, name, command, out, out)
    if name == "get-global":
        identifier = _required_text(args, "identifier", index, name)
        return Step(index, name, {"op": "get_global", "name": identifier, "out": out or identifier}, out, out or identifier)
    if name == "query":
        arguments = args.get("arguments", args.get("args")) or []
        if not isinstance(arguments, list):
            raise BatchError("'arguments' must be a list", index, name)
        command = {"op": "query", "name": _required_text(args, "name", index, name),
                   "args": [unwrap_typed(a) for a in arguments], "out": out}
        return Step(index, name, command, out, out)
    if name == "set-focus":
        return Step(index, name, {"op": "set_focus", "group": _group(args, index, name)})
    if name in ("clear-agenda-group", "clear-ruleflow-group"):  # one concept since Drools 6
        return Step(index, name, {"op": "clear_agenda_group", "group": _group(args, index, name)})
    if name == "clear-activation-group":
        return Step(index, name, {"op": "clear_activation_group", "group": _group(args, index, name)})
    if name == "clear-agenda":
        return Step(index, name, {"op": "clear_agenda"})
    if name == "advance-session-time":
        unit = str(args.get("unit") or "MILLISECONDS").upper()
        if unit not in TIME_UNITS_MS:
            raise BatchError(f"unit must be one of {', '.join(TIME_UNITS_MS)}, got {unit!r}", index, name)
        amount = _int(args.get("amount", 0), index, name, "amount")
        if amount < 0:
            raise BatchError("amount must not be negative: the clock cannot go back", index, name)
        key = out or "session-advancecurrenttime"  # KIE's default out-identifier
        return Step(index, name, {"op": "advance", "ms": int(amount * TIME_UNITS_MS[unit]), "out": key}, key, key)
    if name == "get-session-time":
        key = out or "session-currenttime"
        return Step(index, name, {"op": "get_time", "out": key}, key, key)
    if name == "get-fact-handles":
        return Step(index, name, {"op": "get_fact_handles", "ep": "DEFAULT", "out": out}, out, out)  # as getObjects()
    if name == "dispose":
        return Step(index, name, {"op": "dispose"})
    known = ("insert, insert-elements, fire-all-rules, get-objects, get-object, retract (delete), modify, update, "
             "set-global, get-global, query, set-focus, clear-agenda, clear-agenda-group, clear-activation-group, "
             "clear-ruleflow-group, advance-session-time, get-session-time, get-fact-handles, dispose")
    raise BatchError(f"unknown command '{name}' (KIE's rule commands: {known})", index, name)


def _required(args: dict[str, Any], key: str, index: int, name: str) -> Any:
    if args.get(key) is None:
        raise BatchError(f"'{key}' is required", index, name)
    return args[key]


def _required_text(args: dict[str, Any], key: str, index: int, name: str) -> str:
    value = args.get(key)
    if not isinstance(value, str) or not value:
        raise BatchError(f"'{key}' is required (a string)", index, name)
    return value


def _int(value: Any, index: int, name: str, key: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        raise BatchError(f"'{key}' must be an integer, got {value!r}", index, name)
    try:
        return int(value)
    except ValueError:
        raise BatchError(f"'{key}' must be an integer, got {value!r}", index, name) from None


def _entry_point(args: dict[str, Any]) -> str:
    return str(args.get("entry-point") or args.get("entryPoint") or "DEFAULT")


def _group(args: dict[str, Any], index: int, name: str) -> str:
    for key in ("name", "agenda-group", "agendaGroup", "group"):
        if isinstance(args.get(key), str) and args[key]:
            return args[key]
    raise BatchError("'name' (the agenda group) is required", index, name)


def _class_filter(args: dict[str, Any], index: int, name: str) -> str | None:
    value = args.get("class-object-filter", args.get("classObjectFilter"))
    if isinstance(value, dict):
        value = next((value[k] for k in ("string", "class-name", "className", "clazz", "type") if value.get(k)), None)
    if value is None or value in ("", "java.lang.Object"):
        return None
    if not isinstance(value, str):
        raise BatchError("'class-object-filter' must name a class", index, name)
    return value


def _setters(args: dict[str, Any], index: int, name: str) -> list[list[Any]]:
    raw = args.get("setters", args.get("setter", []))
    if isinstance(raw, dict):
        raw = [raw]  # KIE's documentation sends one setter as an object
    if not isinstance(raw, list):
        raise BatchError("'setters' must be a list of {\"accessor\", \"value\"}", index, name)
    out = []
    for k, setter in enumerate(raw):
        if not isinstance(setter, dict) or not isinstance(setter.get("accessor"), str) or not setter["accessor"]:
            raise BatchError(f"setter {k} must be {{\"accessor\": \"<field>\", \"value\": ...}}", index, name)
        out.append([setter["accessor"], unwrap_typed(setter.get("value"))])
    return out


def fact_handle_text(args: dict[str, Any], index: int, name: str) -> str:
    """A fact handle as KIE clients send it: the external form, or the object KIE returned."""
    value = args.get("fact-handle", args.get("factHandle", args.get("handle")))
    for _ in range(3):
        if isinstance(value, dict):
            if "external-form" in value:
                value = value["external-form"]
            elif "externalForm" in value:
                value = value["externalForm"]
            elif len(value) == 1:
                value = next(iter(value.values()))  # {"org.drools.core.common.DefaultFactHandle": {...}}
    if not isinstance(value, str) or not value:
        raise BatchError("'fact-handle' is required: the handle's external form (0:id:…), as insert returned it",
                         index, name)
    return value


def fact_from_kie(obj: Any, index: int, name: str, element: int | None = None) -> dict[str, Any]:
    """``{"org.pkg.Customer": {...}}`` (or a simple name, or ``{"containedObject": {"@class": …}}``) ->
    ``{"type": "org.pkg.Customer", ...}``; the rule set's types then decide whether it exists."""
    where = f"object {element}: " if element is not None else ""
    if isinstance(obj, dict) and "containedObject" in obj and len(obj) == 1:
        obj = obj["containedObject"]
    if isinstance(obj, dict) and "@class" in obj:
        fields = {k: v for k, v in obj.items() if k != "@class"}
        fqcn = obj["@class"]
    elif isinstance(obj, dict) and len(obj) == 1:
        fqcn, fields = next(iter(obj.items()))
    else:
        raise BatchError(f"{where}the object must be {{\"<package>.<Type>\": {{fields}}}}", index, name)
    if not isinstance(fqcn, str) or not fqcn or not isinstance(fields, dict):
        raise BatchError(f"{where}the object must be {{\"<package>.<Type>\": {{fields}}}}", index, name)
    if "type" in fields:
        raise BatchError(f"{where}the field name 'type' is reserved by the gateway", index, name)
    return {"type": fqcn, **{k: unwrap_nested(v) for k, v in fields.items()}}


_CLASS_NAME = re.compile(r"^[A-Za-z_$][\w$]*(\.[A-Za-z_$][\w$]*)+$")


def unwrap_typed(value: Any) -> Any:
    """KIE clients send typed values, ``{"java.lang.Integer": 18}`` or ``{"org.pkg.Person": {…}}``
    (a global or query argument of a declared type); plain JSON works too."""
    if isinstance(value, dict) and len(value) == 1:
        key = next(iter(value))
        if _CLASS_NAME.match(key):
            return value[key]
    return value


def unwrap_nested(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: unwrap_nested(v) for k, v in unwrap_typed(value).items()} if isinstance(unwrap_typed(value), dict) \
            else unwrap_typed(value)
    if isinstance(value, list):
        return [unwrap_nested(v) for v in value]
    return value


# --- answers ---------------------------------------------------------------------------------


class Marshal:
    """Objects in KIE's JSON: ``{"<fully qualified type>": {fields}}``."""

    def __init__(self, type_names: dict[str, str]) -> None:
        self.type_names = type_names  # simple -> fully qualified (the rule set's)

    def object(self, value: Any) -> Any:
        if isinstance(value, dict) and isinstance(value.get("type"), str):
            simple = value["type"]
            fields = {k: self.plain(v) for k, v in value.items() if k != "type"}
            return {self.type_names.get(simple, simple): fields}
        if isinstance(value, list):
            return [self.object(v) for v in value]
        return value

    def plain(self, value: Any) -> Any:
        """A nested value: declared objects without their wrapper (as KIE's marshaller writes fields)."""
        if isinstance(value, dict):
            return {k: self.plain(v) for k, v in value.items() if k != "type"}
        if isinstance(value, list):
            return [self.plain(v) for v in value]
        return value

    @staticmethod
    def handle(text: str) -> dict[str, Any]:
        return {FACT_HANDLE: {"external-form": text}}

    def query(self, value: dict[str, Any]) -> dict[str, Any]:
        """KIE's ``FlatQueryResults``: per row, the values and the ``DisconnectedFactHandle`` of each
        identifier that has a fact handle (query parameters included, as KIE)."""
        rows = [_map([(k, self.object(v)) for k, v in row.items()]) for row in value["rows"]]
        handles = [_map([(k, {DISCONNECTED_HANDLE: self.disconnected(h)}) for k, h in row.items()])
                   for row in value.get("handles") or [{} for _ in rows]]
        return {FLAT_QUERY_RESULTS: {
            "idFactHandleMaps": {"type": "LIST", "componentType": None, "element": handles},
            "idResultMaps": {"type": "LIST", "componentType": None, "element": rows},
            "identifiers": {"type": "SET", "componentType": None, "element": value["identifiers"]},
        }}

    def disconnected(self, handle: dict[str, Any]) -> dict[str, Any]:
        """A fact handle as KIE Server's JSON writes a ``DisconnectedFactHandle`` (object included)."""
        return {"id": handle["id"], "identityHashCode": handle["identityHashCode"], "objectHashCode": handle["objectHashCode"],
                "recency": handle["recency"], "object": self.object(handle.get("object")), "traitType": handle["traitType"],
                "external-form": handle["external"]}


def _map(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A map as KIE's JAXB list adapter writes it in JSON."""
    return {"type": "MAP", "componentType": None, "element": [{"key": k, "value": v} for k, v in pairs]}


def execution_results(batch: Batch, results: list[dict[str, Any]], marshal: Marshal) -> dict[str, Any]:
    """``{"results": [{"key", "value"}], "facts": [{"key", "value"}]}`` as KIE Server answers: one
    entry per key (KIE's ``ExecutionResultImpl`` keeps maps, so a key used twice holds the last value)."""
    by_index = {r["i"]: r for r in results}
    out_results: dict[str, Any] = {}
    out_facts: dict[str, Any] = {}
    for step in batch.steps:
        if step.command is None:
            continue
        result = by_index.get(_command_index(batch, step))
        if result is None:
            continue
        op = step.command["op"]
        if step.value_key is not None:
            value: Any
            if op == "fire":
                value = int(result.get("fire", {}).get("fireCount", 0))
            elif op == "query":
                value = marshal.query(result["value"])
            elif op == "get_fact_handles":
                value = [marshal.handle(h) for h in result.get("value") or []]
            elif op in ("advance", "get_time"):
                value = result.get("value")
            elif "value" in result:
                value = marshal.object(result["value"])
            else:
                continue
            out_results[step.value_key] = value
        if step.fact_key is not None and result.get("handles"):
            handles = [marshal.handle(h) for h in result["handles"]]
            out_facts[step.fact_key] = handles if step.many else handles[0]
    return {"results": [{"key": k, "value": v} for k, v in out_results.items()],
            "facts": [{"key": k, "value": v} for k, v in out_facts.items()]}


def _command_index(batch: Batch, step: Step) -> int:
    """Session commands are numbered without the steps answered here (none today: kept explicit)."""
    return sum(1 for s in batch.steps[: step.index] if s.command is not None)
