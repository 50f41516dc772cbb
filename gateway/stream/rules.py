"""Query results → facts of a rule set: each result row becomes one fact and the rules fire.

Why a binding object: a detected event (a customer entered) is only useful once the business rules
see it. The binding names the rule set, the declared fact type (e.g. ``CustomerEntered``) and which
row variable fills which field; values are converted to the declared field types, IRIs shortened
to their local names (``…/entrance/c1`` → ``c1``) unless ``local_names`` is off.

Two modes: ``stateless`` (default; ``engine.fire(ruleset, facts)`` per window, nothing kept) or
``stateful`` (one long-lived session per binding; facts are inserted as events at the window's end
time, so temporal rules work; bound memory with ``@expires`` in the DRL).

What else a rule set needs besides the rows is declared here too, so no code is written per use
case (the teahouse reception is only data, ``ontology/queries/customer_detection.binding.yaml``):

- ``constants``: fact fields with fixed values (``entrance: entrance``);
- ``attributes``: fact fields filled with the latest value, in the window, of a property of the
  row's subject (``age: printeps:age`` — the subject is the row variable ``subject``, default the
  first bound field that is an IRI);
- ``window_facts``: facts made once per fired window (``{type: Entrance, fields: {id: entrance,
  number_of_customers: $rows}}``; ``$rows``, ``$window_start`` and ``$window_end`` are replaced);
- ``context``: facts from the gateway's providers (``robots``: one ``Robot`` fact per robot with
  its position);
- ``suppress_repeats: {key: s, for_s: 30}``: a row whose key already fired within that many
  seconds of event time is left out (a party is greeted once, not every window);
- ``dispatch``: whether the then-part's actions go to the robots when the gateway runs ROS.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Mapping

from pyoxigraph import BlankNode, NamedNode

from gateway.rdf.terms import DEFAULT_PREFIXES, Term, local_name, parse_node, term_to_json

_INT_TYPES = {"int", "integer", "long", "short", "byte", "java.lang.integer", "java.lang.long"}
_FLOAT_TYPES = {"double", "float", "java.lang.double", "java.lang.float", "bigdecimal", "java.math.bigdecimal"}
_BOOL_TYPES = {"boolean", "java.lang.boolean"}


class BindingError(ValueError):
    """A binding that cannot work (unknown rule set/type/field or variable)."""


@dataclass
class RuleBinding:
    """Which rule set a query feeds, as which fact type, with which fields (see the module docstring)."""

    ruleset: str
    fact_type: str
    fields: dict[str, str] | None = None  # fact field -> query variable; default: same names
    mode: str = "stateless"  # or "stateful"
    local_names: bool = True
    constants: dict[str, Any] = field(default_factory=dict)
    attributes: dict[str, str] = field(default_factory=dict)
    subject: str | None = None
    window_facts: list[dict[str, Any]] = field(default_factory=list)
    context: list[str] = field(default_factory=list)
    suppress_repeats: dict[str, Any] | None = None
    dispatch: bool = True
    on_deploy: str | None = None  # a stateful binding's session on a deploy: "follow" | "pin" (None: sessions.on_deploy)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, raw: Any, where: str = "rules") -> "RuleBinding":
        """A binding from its JSON/YAML form; BindingError names the bad field (``rules.fields``)."""
        if not isinstance(raw, Mapping) or not isinstance(raw.get("ruleset"), str) \
                or not isinstance(raw.get("fact_type"), str):
            raise BindingError(f"{where}: must be {{\"ruleset\": …, \"fact_type\": …, \"fields\"?, …}}")
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(raw) - known)
        if unknown:
            raise BindingError(f"{where}.{unknown[0]}: unknown key; known: {', '.join(sorted(known))}")
        fields = raw.get("fields")
        if fields is not None and (not isinstance(fields, Mapping) or not all(isinstance(v, str) for v in fields.values())):
            raise BindingError(f"{where}.fields: must map fact fields to query variable names")
        attributes = raw.get("attributes") or {}
        if not isinstance(attributes, Mapping) or not all(isinstance(v, str) for v in attributes.values()):
            raise BindingError(f"{where}.attributes: must map fact fields to predicates (printeps:age)")
        constants = raw.get("constants") or {}
        if not isinstance(constants, Mapping):
            raise BindingError(f"{where}.constants: must map fact fields to values")
        window_facts = raw.get("window_facts") or []
        if not isinstance(window_facts, list) or not all(
                isinstance(w, Mapping) and isinstance(w.get("type"), str) and isinstance(w.get("fields", {}), Mapping)
                for w in window_facts):
            raise BindingError(f"{where}.window_facts: must be a list of {{type, fields}}")
        context = raw.get("context") or []
        if not isinstance(context, list) or not all(isinstance(c, str) for c in context):
            raise BindingError(f"{where}.context: must be a list of provider names")
        repeats = raw.get("suppress_repeats")
        if repeats is not None and (not isinstance(repeats, Mapping) or not isinstance(repeats.get("key"), str)
                                    or not isinstance(repeats.get("for_s", 0), (int, float))):
            raise BindingError(f"{where}.suppress_repeats: must be {{key: <variable>, for_s: <seconds>}}")
        return cls(ruleset=raw["ruleset"], fact_type=raw["fact_type"],
                   fields={k: v.lstrip("?") for k, v in fields.items()} if fields else None,
                   mode=str(raw.get("mode", "stateless")), local_names=bool(raw.get("local_names", True)),
                   constants=dict(constants), attributes=dict(attributes),
                   subject=str(raw["subject"]).lstrip("?") if raw.get("subject") else None,
                   window_facts=[dict(w) for w in window_facts], context=list(context),
                   suppress_repeats=dict(repeats) if repeats else None, dispatch=bool(raw.get("dispatch", True)),
                   on_deploy=str(raw["on_deploy"]) if raw.get("on_deploy") is not None else None)


def check_binding(binding: RuleBinding, variables: list[str], engine: Any,
                  providers: Mapping[str, Any] | None = None) -> dict[str, dict[str, str]]:
    """Validate against the query's variables and the rule set's declared types; returns the
    declared field types of every fact type the binding makes (``{type: {field: java type}}``)."""
    if binding.mode not in ("stateless", "stateful"):
        raise BindingError(f"mode must be 'stateless' or 'stateful', not {binding.mode!r}")
    if binding.on_deploy not in (None, "follow", "pin"):
        raise BindingError(f"on_deploy must be 'follow' or 'pin', not {binding.on_deploy!r}")
    try:
        declared = engine.declared_types(binding.ruleset)
    except LookupError as exc:
        raise BindingError(f"ruleset: {exc}; deploy it first or bind to a deployed rule set") from exc

    def fields_of(fact_type: str, where: str) -> dict[str, str]:
        if fact_type not in declared:
            raise BindingError(f"{where}: rule set {binding.ruleset!r} declares no type {fact_type!r}; "
                               f"declared: {sorted(declared)}")
        return {k: str(v) for k, v in declared[fact_type].items()}

    field_types = fields_of(binding.fact_type, "fact_type")
    fields = binding.fields or {v: v for v in variables if v in field_types}
    for name, var in fields.items():
        if name not in field_types:
            raise BindingError(f"{binding.fact_type} has no field {name!r}; fields: {sorted(field_types)}")
        if var not in variables:
            raise BindingError(f"field {name!r}: the query has no variable ?{var}; variables: {variables}")
    if not fields:
        raise BindingError(f"no query variable matches a field of {binding.fact_type}; give 'fields'")
    binding.fields = dict(fields)
    for group in ("constants", "attributes"):
        for name in getattr(binding, group):
            if name not in field_types:
                raise BindingError(f"{group}.{name}: {binding.fact_type} has no field {name!r}; "
                                   f"fields: {sorted(field_types)}")
    if binding.subject is not None and binding.subject not in variables:
        raise BindingError(f"subject: the query has no variable ?{binding.subject}; variables: {variables}")
    if binding.suppress_repeats and binding.suppress_repeats["key"].lstrip("?") not in variables:
        raise BindingError(f"suppress_repeats.key: the query has no variable ?{binding.suppress_repeats['key']}")
    types = {binding.fact_type: field_types}
    for i, spec in enumerate(binding.window_facts):
        wtypes = fields_of(spec["type"], f"window_facts[{i}].type")
        for name in spec.get("fields", {}):
            if name not in wtypes:
                raise BindingError(f"window_facts[{i}].fields.{name}: {spec['type']} has no field {name!r}; "
                                   f"fields: {sorted(wtypes)}")
        types[spec["type"]] = wtypes
    for name in binding.context:
        if providers is None or name not in providers:
            raise BindingError(f"context: no fact provider {name!r} on this gateway; "
                               f"known: {sorted(providers or {})}")
    return types


def binding_facts(binding: RuleBinding, rows: list[dict[str, Term]], types: dict[str, dict[str, str]],
                  window: Any, providers: Mapping[str, Callable[[], list[dict[str, Any]]]] | None = None,
                  handled: dict[str, int] | None = None) -> list[dict[str, Any]]:
    """The facts one window's rows give the rule set (rows, window facts, context); [] when every
    row was suppressed as a repeat (nothing to fire)."""
    field_types = types[binding.fact_type]
    kept = _fresh_rows(binding, rows, window.end_ms, handled) if binding.suppress_repeats else rows
    if not kept:
        return []
    attributes = _attribute_index(binding, window) if binding.attributes else {}
    facts = []
    for row in kept:
        fact = row_to_fact(row, binding, field_types)
        for name, value in binding.constants.items():
            fact[name] = _coerce(value, field_types.get(name, ""))
        if binding.attributes:
            subject = _subject_term(binding, row)
            for name, predicate in binding.attributes.items():
                term = attributes.get((subject, predicate))
                if term is not None:
                    fact[name] = _convert(term, field_types.get(name, ""), binding.local_names)
        facts.append(fact)
    specials = {"$rows": len(facts), "$window_start": window.start_ms, "$window_end": window.end_ms}
    for spec in binding.window_facts:
        wtypes = types[spec["type"]]
        fact = {"type": spec["type"]}
        for name, value in spec.get("fields", {}).items():
            value = specials.get(value, value) if isinstance(value, str) else value
            fact[name] = _coerce(value, wtypes.get(name, ""))
        facts.append(fact)
    for name in binding.context:
        facts.extend((providers or {})[name]())
    return facts


def _fresh_rows(binding: RuleBinding, rows: list[dict[str, Term]], end_ms: int,
                handled: dict[str, int] | None) -> list[dict[str, Term]]:
    spec = binding.suppress_repeats or {}
    key, window_ms = spec["key"].lstrip("?"), int(float(spec.get("for_s", 0)) * 1000)
    if handled is None:
        handled = {}
    for k in [k for k, t in handled.items() if end_ms - t >= window_ms]:
        del handled[k]
    fresh = []
    for row in rows:
        term = row.get(key)
        value = str(term_to_json(term)) if term is not None else ""
        if value in handled:
            continue
        handled[value] = end_ms
        fresh.append(row)
    return fresh


def _subject_term(binding: RuleBinding, row: dict[str, Term]) -> Term | None:
    if binding.subject is not None:
        return row.get(binding.subject)
    for var in (binding.fields or {}).values():
        term = row.get(var)
        if isinstance(term, (NamedNode, BlankNode)):
            return term
    return None


def _attribute_index(binding: RuleBinding, window: Any) -> dict[tuple[Term, str], Term]:
    """(subject, predicate as written) -> the object of its latest occurrence in the window."""
    wanted = {parse_node(p, "attributes", DEFAULT_PREFIXES).value: p for p in binding.attributes.values()}
    latest: dict[tuple[Term, str], tuple[int, Term]] = {}
    for (s, p, o), ts in window.stamped.items():
        written = wanted.get(p.value)
        if written is None:
            continue
        seen = latest.get((s, written))
        if seen is None or ts >= seen[0]:
            latest[(s, written)] = (ts, o)
    return {k: v[1] for k, v in latest.items()}


def _coerce(value: Any, java_type: str) -> Any:
    """A declared constant as the field's type (YAML gives text or numbers)."""
    kind = java_type.lower()
    try:
        if kind in _INT_TYPES:
            return int(value)
        if kind in _FLOAT_TYPES:
            return float(value)
        if kind in _BOOL_TYPES:
            return value if isinstance(value, bool) else str(value).lower() in ("true", "1", "yes")
        if kind in ("string", "java.lang.string"):
            return str(value)
    except (TypeError, ValueError):
        return value
    return value


def row_to_fact(row: dict[str, Term], binding: RuleBinding, field_types: dict[str, str]) -> dict[str, Any]:
    """One result row as a fact dict for the engine (``{"type": …, field: value}``)."""
    fact: dict[str, Any] = {"type": binding.fact_type}
    for name, var in (binding.fields or {}).items():
        term = row.get(var)
        if term is None:
            continue
        fact[name] = _convert(term, field_types.get(name, ""), binding.local_names)
    return fact


def _convert(term: Term, java_type: str, local: bool) -> Any:
    value = term_to_json(term)
    if isinstance(term, (NamedNode, BlankNode)):
        value = local_name(term.value) if local else value
    kind = java_type.lower()
    try:
        if kind in _INT_TYPES:
            return int(float(value)) if not isinstance(value, bool) else int(value)
        if kind in _FLOAT_TYPES:
            return float(value)
        if kind in _BOOL_TYPES:
            return bool(value)
        if kind in ("string", "java.lang.string"):
            return str(value)
    except (TypeError, ValueError):
        return value
    return value
