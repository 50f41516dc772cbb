"""What the request-join network of a set (docs/engine-api.md, "Request joins") needs to know
about all of the set's plain rules at once, where each unit is built alone: which first patterns
open more than one rule, and which rules join as an auto-focus rule does."""

from __future__ import annotations

import json
from typing import Any


def first_pattern(rule: dict[str, Any]) -> str | None:
    """A rule's first pattern as Drools compares it for sharing: its type (simple name, so two
    spellings of one type count as one) and its constraints; None when it opens otherwise."""
    lhs = rule.get("lhs") or []
    pattern = lhs[0].get("pattern") if lhs and isinstance(lhs[0], dict) else None
    if not isinstance(pattern, dict):
        return None
    return json.dumps([str(pattern.get("type", "")).rsplit(".", 1)[-1], pattern.get("constraints")], sort_keys=True)


def shared_first_patterns(descriptions: list[dict[str, Any]]) -> set[str]:
    """The first patterns that open two rules or more, across every unit of the set."""
    counts: dict[str, int] = {}
    for description in descriptions:
        for rule in description.get("rules", []):
            first = first_pattern(rule)
            if first is not None:
                counts[first] = counts.get(first, 0) + 1
    return {first for first, n in counts.items() if n > 1}


def _element(element: Any) -> str:
    """One condition element as Drools compares it for sharing (the names it binds aside)."""
    if isinstance(element, dict) and isinstance(element.get("pattern"), dict):
        element = {**element, "pattern": {k: v for k, v in element["pattern"].items() if k not in ("var", "binds")}}
    return json.dumps(element, sort_keys=True)


def _auto_focus(rule: dict[str, Any]) -> bool:
    return bool((rule.get("attributes") or {}).get("auto-focus"))


def _prefixes(rule: dict[str, Any]) -> list[str]:
    """The rule's condition prefixes of two elements or more, shortest first, as far as its
    elements are patterns (joins)."""
    elements = rule.get("lhs") or []
    joins = next((k for k, e in enumerate(elements) if not (isinstance(e, dict) and "pattern" in e)), len(elements))
    lhs = [_element(e) for e in elements[:joins]]
    return [json.dumps(lhs[:k]) for k in range(2, len(lhs) + 1)]


def guarded_prefixes(descriptions: list[dict[str, Any]]) -> None:
    """Marks (``guardedPrefix``: k) each rule without auto-focus whose first k ≥ 2 condition
    elements are patterns (a first pattern and joins) and an auto-focus rule's first k.

    Why: the request-join network puts a guard before each pattern or ``exists`` after an
    auto-focus rule's first (``PlainRequestJoins.linkGuard``: it links as the rule base's node
    does). Drools shares a rule's nodes with another rule that opens alike, and the order a
    shared node hands its matches on depends on the nodes it is shared with; a rule that joins as
    an auto-focus rule does gets the same guards, so that it shares them as in the rule base (such
    join rules fired their matches in another order otherwise). Only joins, measured: a rule that
    shares an ``exists`` with an auto-focus rule answers as the rule base without the guards, and
    not with them (docs/benchmarks.md)."""
    focused = {prefix for description in descriptions for rule in description.get("rules", [])
               if _auto_focus(rule) for prefix in _prefixes(rule)}
    if not focused:
        return
    for description in descriptions:
        for rule in description.get("rules", []):
            if _auto_focus(rule):
                continue
            shared = [k for k, prefix in enumerate(_prefixes(rule), start=2) if prefix in focused]
            if shared:
                rule["guardedPrefix"] = max(shared)


def mark_shared(descriptions: list[dict[str, Any]]) -> list[list[int]]:
    """Marks (``firstShared``) the rules of each unit whose first pattern opens another rule too,
    and those that join as an auto-focus rule does (:func:`guarded_prefixes`); returns what it marked,
    unit by unit (for the cache key of the unit's build).

    Why: Drools shares such a pattern's nodes between the rules, and the order each of them fires
    its matches in depends on that sharing; the request-join network does not dispatch those
    patterns by value (RequestDispatch.java), so that they share as in the rule base (two rules of
    one ``in`` pattern fired their matches in opposite orders otherwise)."""
    shared = shared_first_patterns(descriptions)
    guarded_prefixes(descriptions)
    out = []
    for description in descriptions:
        marked = []
        for k, rule in enumerate(description.get("rules", [])):
            if first_pattern(rule) in shared:
                rule["firstShared"] = True
            if rule.get("firstShared") or rule.get("guardedPrefix"):
                marked.append(k * 1000 + rule.get("guardedPrefix", 0))
        out.append(marked)
    return out
