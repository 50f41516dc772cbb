"""What the request-join network of a set (docs/engine-api.md, "Request joins") needs to know
about all of the set's plain rules at once, where each unit is built alone: which first patterns
open more than one rule, and which rules open as an auto-focus rule does.

Each plain unit's rules are read once (:func:`unit_shapes`, kept per unit id: a unit's id is made
from its content); a deploy then only compares the shapes of all units (:func:`marks`). Why: at
10,000 rules, parsing every unit's description and writing its elements out again at each deploy
took ~0.6 s."""

from __future__ import annotations

import json
import threading
from collections import Counter, OrderedDict
from dataclasses import dataclass
from typing import Any

#: How many units' shapes are kept (a unit holds up to a few thousand rules).
MAX_KEPT_UNITS = 256

_kept: OrderedDict[str, list[RuleShape]] = OrderedDict()
_kept_lock = threading.Lock()


@dataclass(frozen=True)
class RuleShape:
    """How a rule opens, as Drools compares its nodes for sharing."""

    first: str | None  # its first pattern; None when it opens otherwise
    prefixes: tuple[str, ...]  # its first two condition elements or more, shortest first
    auto_focus: bool
    first_test: str | None = None  # its first pattern's type and first constraint (Drools' node under the type's)


def _type_name(pattern: dict[str, Any]) -> str:
    """A pattern's type by its simple name, so that two spellings of one type count as one."""
    return str(pattern.get("type", "")).rsplit(".", 1)[-1]


def _element(element: Any) -> str:
    """One condition element as Drools compares it for sharing: a pattern by its type and its
    constraints, the names it binds aside."""
    pattern = element.get("pattern") if isinstance(element, dict) else None
    if isinstance(pattern, dict):
        element = {"pattern": [_type_name(pattern), pattern.get("constraints")]}
    return json.dumps(element, sort_keys=True)


def _is_pattern(element: Any) -> bool:
    return isinstance(element, dict) and isinstance(element.get("pattern"), dict)


def rule_shape(rule: dict[str, Any]) -> RuleShape:
    elements = rule.get("lhs") or []
    opening = [_element(e) for e in elements]
    pattern = elements[0]["pattern"] if elements and _is_pattern(elements[0]) else None
    first_test = None
    if pattern is not None and pattern.get("constraints"):
        first_test = json.dumps([_type_name(pattern), pattern["constraints"][0]], sort_keys=True)
    return RuleShape(opening[0] if pattern is not None else None,
                     tuple(json.dumps(opening[:k]) for k in range(2, len(opening) + 1)),
                     bool((rule.get("attributes") or {}).get("auto-focus")), first_test)


def unit_shapes(unit_id: str, data: bytes) -> list[RuleShape]:
    """The shapes of a plain unit's rules (``data``: its description), read once per unit."""
    with _kept_lock:
        shapes = _kept.get(unit_id)
        if shapes is not None:
            _kept.move_to_end(unit_id)
            return shapes
    shapes = [rule_shape(rule) for rule in json.loads(data).get("rules", [])]
    with _kept_lock:
        _kept[unit_id] = shapes
        while len(_kept) > MAX_KEPT_UNITS:
            _kept.popitem(last=False)
    return shapes


def marks(units: list[list[RuleShape]]) -> list[dict[int, dict[str, Any]]]:
    """For each unit, the marks of its rules by position:

    - ``firstShared``: the rule's first pattern opens another rule too, or its first test is an
      auto-focus rule's first test. Drools shares such a pattern's nodes between the rules, and
      the order each of them fires its matches in depends on that sharing; the request-join
      network does not dispatch those patterns by value (RequestDispatch.java), so that they share
      as in the rule base (two rules of one ``in`` pattern fired their matches in opposite orders
      otherwise). A shared first test is one alpha node whose children Drools orders by how many
      of them test one field (hashed from three, range-indexed from nine); an auto-focus rule of
      one pattern gets its match, and pushes its agenda group, when a fact reaches its node, so
      taking the other rules out from under that node changed which group fired first.
    - ``guardedPrefix``: k, for a rule without auto-focus whose first k ≥ 2 condition elements are
      an auto-focus rule's first k. The request-join network puts a guard before each pattern or
      ``exists`` after an auto-focus rule's first (``PlainRequestJoins.linkGuard``: it links as the
      rule base's node does); a rule that opens as an auto-focus rule does gets the same guards, so
      that it shares them as it shares the join or ``exists`` node in the rule base. Where two
      rules share a node, the second of its children gets the node's matches in the opposite order
      (``SegmentPropagator``), so a rule not shared as in the rule base fires its matches in
      another order.
    """
    firsts = Counter(shape.first for unit in units for shape in unit if shape.first is not None)
    focused = {prefix for unit in units for shape in unit if shape.auto_focus for prefix in shape.prefixes}
    focused_tests = {shape.first_test for unit in units for shape in unit if shape.auto_focus and shape.first_test}
    out = []
    for unit in units:
        unit_marks: dict[int, dict[str, Any]] = {}
        for k, shape in enumerate(unit):
            mark: dict[str, Any] = {}
            if (shape.first is not None and firsts[shape.first] > 1) or (
                    not shape.auto_focus and shape.first_test in focused_tests):
                mark["firstShared"] = True
            guarded = [n for n, prefix in enumerate(shape.prefixes, start=2) if not shape.auto_focus and prefix in focused]
            if guarded:
                mark["guardedPrefix"] = max(guarded)
            if mark:
                unit_marks[k] = mark
        out.append(unit_marks)
    return out


def with_marks(data: bytes, unit_marks: dict[int, dict[str, Any]]) -> bytes:
    """A unit's description with its rules' marks in them (what ``PlainRules.build`` reads)."""
    description = json.loads(data)
    for k, mark in unit_marks.items():
        description["rules"][k].update(mark)
    return json.dumps(description).encode()
