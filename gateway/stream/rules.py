"""Query results → facts of a rule set: each result row becomes one fact and the rules fire.

Why a binding object: a detected event (a customer entered) is only useful once the business rules
see it. The binding names the rule set, the declared fact type (e.g. ``CustomerEntered``) and which
row variable fills which field; values are converted to the declared field types, IRIs shortened
to their local names (``…/entrance/c1`` → ``c1``) unless ``local_names`` is off.

Two modes: ``stateless`` (default; ``engine.fire(ruleset, facts)`` per window, nothing kept) or
``stateful`` (one long-lived session per binding; facts are inserted as events at the window's end
time, so temporal rules work; bound memory with ``@expires`` in the DRL).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from pyoxigraph import BlankNode, NamedNode

from gateway.rdf.terms import Term, local_name, term_to_json

_INT_TYPES = {"int", "integer", "long", "short", "byte", "java.lang.integer", "java.lang.long"}
_FLOAT_TYPES = {"double", "float", "java.lang.double", "java.lang.float", "bigdecimal", "java.math.bigdecimal"}
_BOOL_TYPES = {"boolean", "java.lang.boolean"}


class BindingError(ValueError):
    """A binding that cannot work (unknown rule set/type/field or variable)."""


@dataclass
class RuleBinding:
    """Which rule set a query feeds, as which fact type, with which fields."""

    ruleset: str
    fact_type: str
    fields: dict[str, str] | None = None  # fact field -> query variable; default: same names
    mode: str = "stateless"  # or "stateful"
    local_names: bool = True

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def check_binding(binding: RuleBinding, variables: list[str], engine: Any) -> dict[str, str]:
    """Validate against the query's variables and the rule set's declared types; returns field types."""
    if binding.mode not in ("stateless", "stateful"):
        raise BindingError(f"mode must be 'stateless' or 'stateful', not {binding.mode!r}")
    declared = engine.declared_types(binding.ruleset)
    if binding.fact_type not in declared:
        raise BindingError(f"rule set {binding.ruleset!r} declares no type {binding.fact_type!r}; "
                           f"declared: {sorted(declared)}")
    field_types = {k: str(v) for k, v in declared[binding.fact_type].items()}
    fields = binding.fields or {v: v for v in variables if v in field_types}
    for field, var in fields.items():
        if field not in field_types:
            raise BindingError(f"{binding.fact_type} has no field {field!r}; fields: {sorted(field_types)}")
        if var not in variables:
            raise BindingError(f"field {field!r}: the query has no variable ?{var}; variables: {variables}")
    if not fields:
        raise BindingError(f"no query variable matches a field of {binding.fact_type}; give 'fields'")
    binding.fields = dict(fields)
    return field_types


def row_to_fact(row: dict[str, Term], binding: RuleBinding, field_types: dict[str, str]) -> dict[str, Any]:
    """One result row as a fact dict for the engine (``{"type": …, field: value}``)."""
    fact: dict[str, Any] = {"type": binding.fact_type}
    for field, var in (binding.fields or {}).items():
        term = row.get(var)
        if term is None:
            continue
        fact[field] = _convert(term, field_types.get(field, ""), binding.local_names)
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
