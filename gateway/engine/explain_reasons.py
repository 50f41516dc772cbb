"""Explain, part 2: the diagnostic queries' rows read back as reasons, rule by rule.

Why apart from the plans: reading a rule and asking Drools are two concerns; this one only knows
a :class:`~gateway.engine.explain_plan.RulePlan`'s query names and what their rows mean: the
first prefix ``C1 … Ck`` with no row is the condition that stopped the rule; inside it, the
candidate fact passing the most constraints came closest and the constraint after them failed
("language is "fr", the rule wants "en""); the facts that exist stop a ``not``; the closest
alternative an ``or``; the element that breaks it a ``forall``. The queries run in a
:class:`ThrowawaySession` (nothing recorded, nothing reaches a robot), asked in two JVM calls
(:func:`prefetch`) rather than one per query.
"""

from __future__ import annotations

import re
from datetime import date
from typing import Any, Callable

import orjson

from gateway.engine import rule_dates
from gateway.engine.errors import FactError
from gateway.engine.explain_plan import FACT, Condition, RulePlan, has_candidates
from gateway.engine.results import FireResult, decode_result, encode_facts

MAX_SHOWN = 10  # facts shown for a condition (the blockers of a "not"); a query's other rows are not read
_FIELD = re.compile(r"^\s*(?:\$?[\w$]+\s*:\s*)?([A-Za-z_$][\w$.]*)")
_EQUALS = re.compile(r"^\s*(?:\$?[\w$]+\s*:\s*)?[A-Za-z_$][\w$.]*\s*==\s*(.+?)\s*$", re.DOTALL)


def _value(fact: Any, path: str) -> Any:
    value = fact
    for part in path.split("."):
        if not isinstance(value, dict):
            return None
        value = value.get(part)
    return value


def _show(value: Any) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def _describe(fact: Any) -> str:
    """A fact in a few words: ``Guest "g1"`` when it has an id or name, else ``Group(kind="pair", size=2)``."""
    if isinstance(fact, dict):
        kind = fact.get("type", "fact")
        ident = fact.get("id") or fact.get("name")
        if ident is not None:
            return f"{kind} {_show(ident)}"
        fields = [f"{k}={_show(v)}" for k, v in fact.items() if k != "type" and not isinstance(v, (dict, list))][:3]
        return f"{kind}({', '.join(fields)})"
    return _show(fact)


def _wants(constraint: str) -> str:
    equals = _EQUALS.match(constraint)
    return equals.group(1).strip() if equals else constraint


class ThrowawaySession:
    """A Java ``Session`` used for one explanation and disposed: insert, fire, query.

    Not a :class:`gateway.engine.session.StatefulSession`: that one is made to live long (it shares
    buffers with the JVM for the stream path, keeps a lock, follows deploys); this one needs none
    of it."""

    def __init__(self, java: Any, fire_limit: int, max_facts: int) -> None:
        self._java = java
        self._fire_limit = fire_limit
        self._max_facts = max_facts

    def insert(self, facts: list[dict[str, Any]]) -> None:
        _checked(self._java.insert(encode_facts(facts, self._max_facts)))

    def fire(self, return_facts: bool = False) -> FireResult:
        return decode_result(str(self._java.fire(self._fire_limit, return_facts)), "(explain)", 0, 0.0)

    def query(self, name: str) -> dict[str, Any]:
        return _checked(self._java.query(str(name), "[]"))

    def queries(self, names: list[str], max_rows: int) -> dict[str, list[dict[str, Any]]]:
        """Several queries in one JVM call, at most ``max_rows`` rows each."""
        return _checked(self._java.queries(orjson.dumps(names).decode(), int(max_rows)))["results"]

    def close(self) -> None:
        self._java.dispose()


def _checked(answer: Any) -> dict[str, Any]:
    data = orjson.loads(str(answer))
    if not data.get("ok"):
        raise FactError(data.get("errors", []), data.get("errorCount"))
    return data


class Run:
    """One explanation's session: the facts inserted and fired, then queried."""

    def __init__(self, session: Any) -> None:
        self.session = session
        self._rows: dict[str, list[dict[str, Any]]] = {}

    def rows(self, name: str) -> list[dict[str, Any]]:
        if name not in self._rows:
            self._rows[name] = self.session.query(name)["rows"]
        return self._rows[name]

    def prefetch(self, names: list[str]) -> None:
        """Ask ``names`` at once (one JVM call): what explaining the rules that did not fire needs.
        Rows beyond MAX_SHOWN are never shown, so they are not fetched."""
        if names:
            self._rows.update(self.session.queries(names, MAX_SHOWN))

    @property
    def fetched(self) -> set[str]:
        return set(self._rows)


def _closest(run: Run, cond: Condition, name: Callable[[int], str]) -> tuple[Any, int]:
    """The candidate fact of ``cond`` that passes the most of its constraints in order, and how
    many it passes (-1: there is no candidate at all); ``name(j)``: the query with j constraints."""
    best, passed = None, -1
    if not has_candidates(cond):  # nothing to ask (no query was made)
        return best, passed
    for j in range(0, len(cond.constraints) + 1):
        rows = run.rows(name(j))
        if not rows:
            break
        best, passed = _candidate(cond, rows[0]), j
    return best, passed


def _candidate(cond: Condition, row: dict[str, Any]) -> Any:
    """What a candidate query's row shows: the fact (``$__f``), or an accumulate element's results
    by the names its functions bind them to (``{"$t": 1200.0}``)."""
    if cond.functions:
        return {name: row.get(name) for name in cond.results()}
    return row.get(FACT)


def _why_pattern(run: Run, plan: RulePlan, k: int, cond: Condition,
                 name: Callable[[int], str] | None = None) -> dict[str, Any]:
    fact, passed = _closest(run, cond, name or (lambda j: plan.candidate_query(k, j)))
    out: dict[str, Any] = {"constraint": None, "closest": None}
    source = f" {cond.suffix}" if cond.kind == "from" else ""
    out["score"] = -1.0
    if passed < 0:  # no candidate at all (or none to ask for: see _closest)
        if cond.kind == "accumulate" and cond.type is None:  # the accumulate element
            out["reason"] = "the accumulate gives no value" if cond.functions else f"{cond.drl} does not hold"
        elif cond.kind == "accumulate":
            out["reason"] = f"the accumulate gives no value ({cond.suffix})"
        else:
            out["reason"] = f"there is no {cond.type} fact{source}"
        return out
    if passed >= len(cond.constraints):  # every constraint holds for some fact: an earlier binding is what fails
        out["reason"] = f"a {cond.type or 'result'} matches its own constraints, but not together with the conditions before it"
        out["closest"] = {"fact": fact}
        out["score"] = 1.0
        return out
    failing = cond.constraints[passed]
    field_match = _FIELD.match(failing)
    field_name = field_match.group(1) if field_match else None
    value = _value(fact, field_name) if field_name and isinstance(fact, dict) else fact
    out["constraint"] = failing
    out["closest"] = {"fact": fact, "passed": passed, "of": len(cond.constraints), "field": field_name,
                      "value": value}
    out["score"] = passed / len(cond.constraints)
    if cond.functions and field_name in fact:  # accumulate( …; $t : sum( $a ); $t > 100 )
        out["reason"] = f"{field_name} is {_show(value)}, the rule wants {failing}"
    elif cond.functions:
        shown = ", ".join(f"{name} = {_show(result)}" for name, result in fact.items())
        out["reason"] = f"the accumulate gives {shown}, the rule wants {failing}"
    elif cond.kind == "accumulate":
        out["reason"] = f"the accumulated value is {_show(fact)}, the rule wants {failing}"
    elif field_name and isinstance(fact, dict) and field_name in fact or "." in (field_name or ""):
        shown = field_name if field_name and "." not in field_name else field_name
        out["reason"] = f"{shown} is {_show(value)}, the rule wants {_wants(failing)} ({_describe(fact)} came closest)"
    else:
        out["reason"] = f"{_describe(fact)} came closest; it fails {failing}"
    if cond.kind == "exists":
        out["reason"] = f"no {cond.type} fact{source} exists that matches; " + out["reason"]
    elif cond.kind == "from":
        out["reason"] = f"no item {cond.suffix} matches; " + out["reason"]
    return out


def _why_alternative(run: Run, plan: RulePlan, k: int, branch: Condition) -> dict[str, Any]:
    """How close one alternative of an "or" came: ``score`` is the share of its constraints the
    closest fact passes (1: it holds on its own, -1: nothing to match at all)."""
    out: dict[str, Any] = {"index": branch.index, "drl": branch.drl}
    if branch.kind == "not":
        blockers = [r.get(FACT) for r in run.rows(plan.branch_query(k, branch.index, len(branch.constraints)))]
        return {**out, "score": -1.0, "exists": blockers[:MAX_SHOWN],
                "reason": f"{_describe(blockers[0])} exists" if blockers else f"a {branch.type} fact exists"}
    if has_candidates(branch):
        why = _why_pattern(run, plan, k, branch, lambda j: plan.branch_query(k, branch.index, j))
        return {**out, **why}
    holds = bool(run.rows(plan.branch_query(k, branch.index)))
    return {**out, "score": 1.0 if holds else -1.0,
            "reason": "it holds on its own, but not with the conditions before it" if holds else "it does not hold"}


def _why_or(run: Run, plan: RulePlan, k: int, cond: Condition) -> dict[str, Any]:
    """Which alternative came closest, and what stopped it; every alternative's reason besides."""
    alternatives = [_why_alternative(run, plan, k, b) for b in cond.branches]
    best = max(alternatives, key=lambda a: a["score"])
    for a in alternatives:
        a.pop("score")
    return {"constraint": best.get("constraint"), "closest": best.get("closest"), "alternatives": alternatives,
            "closest_alternative": best["index"],
            "reason": f"none of its {len(alternatives)} alternatives holds; the closest is alternative "
                      f"{best['index']} ({best['drl']}): {best['reason']}"}


def _why_forall(run: Run, plan: RulePlan, k: int, cond: Condition) -> dict[str, Any]:
    """The element that breaks the forall, and what it lacks (the constraint it fails, for a
    forall of one pattern; the patterns it has no match in, for more)."""
    first, rest = cond.branches[0], cond.branches[1:]
    key = first.binding if rest and first.binding else FACT
    violators = [r.get(key) for r in run.rows(plan.violators_query(k))]
    if not violators:
        return {"constraint": None, "reason": f"the forall ({cond.drl}) does not hold with the conditions before it"}
    fact = violators[0]
    out: dict[str, Any] = {"violating": violators[:MAX_SHOWN]}
    if rest:
        wanted = " and ".join(r.drl for r in rest)
        return {**out, "constraint": wanted,
                "reason": f"{_describe(fact)} matches {first.drl} but has no {wanted}: the rule wants it for every "
                          f"such {first.type} ({len(violators)} without)"}
    for j, constraint in enumerate(first.constraints):
        if any(r.get(FACT) == fact for r in run.rows(plan.violators_query(k, j))):
            field_match = _FIELD.match(constraint)
            field_name = field_match.group(1) if field_match else None
            if field_name and isinstance(fact, dict) and field_name in fact:
                detail = f"{field_name} is {_show(fact[field_name])}, the rule wants {_wants(constraint)}"
            else:
                detail = f"it fails {constraint}"
            return {**out, "constraint": constraint,
                    "reason": f"{_describe(fact)} breaks the forall: {detail} for every {first.type}"}
    return {**out, "constraint": None, "reason": f"{_describe(fact)} does not match {first.drl}"}


def prefetch(run: Run, plans: list[RulePlan]) -> None:
    """Ask, in two JVM calls, the queries explaining ``plans`` (the rules that did not fire) will
    read: every prefix ``C1 … Ck``, then the candidate queries of each rule's first failing
    condition. One call per query cost more than the queries (~95 calls for the reception set)."""
    run.prefetch([plan.prefix_query(k) for plan in plans for k in range(1, len(plan.conditions) + 1)])
    second = []
    for plan in plans:
        k = next((k for k in range(1, len(plan.conditions) + 1) if not run.rows(plan.prefix_query(k))), None)
        if k is not None:
            second.extend(plan.condition_names(k))
    run.prefetch([name for name in second if name not in run.fetched])


def explain_rule(run: Run, plan: RulePlan, fired: list[list[Any]], groups_fired: frozenset[str] = frozenset()
                 ) -> dict[str, Any]:
    """What one rule did: fired with its matches, or the condition that stopped it and why
    (``groups_fired``: the activation groups in which a rule fired)."""
    base: dict[str, Any] = {"rule": plan.name, "file": plan.file, "line": plan.line}
    if fired:
        return {**base, "fired": True, "matches": fired}
    if plan.broken:
        return {**base, "fired": False, "reason": f"cannot be explained: {plan.broken}"}
    for k, cond in enumerate(plan.conditions, start=1):
        if run.rows(plan.prefix_query(k)):
            continue
        out = {**base, "fired": False, "condition": {**cond.where(), "of": len(plan.conditions)}}
        if cond.kind == "not":
            blockers = [r.get(FACT) for r in run.rows(plan.candidate_query(k, len(cond.constraints)))]
            out.update(constraint=None, exists=blockers[:MAX_SHOWN],
                       reason=f"{_describe(blockers[0])} exists, and the rule wants no such {cond.type}"
                       if blockers else f"a {cond.type} fact exists, and the rule wants none")
        elif cond.kind in ("pattern", "exists", "from", "accumulate"):
            out.update(_why_pattern(run, plan, k, cond))
            out.pop("score", None)
        elif cond.kind == "or":
            out.update(_why_or(run, plan, k, cond))
        elif cond.kind == "forall":
            out.update(_why_forall(run, plan, k, cond))
        elif cond.kind == "eval":
            out.update(constraint=cond.drl, reason=f"{cond.drl} is false")
        else:
            out.update(constraint=None, reason=f"condition {k} ({cond.drl}) does not hold")
        return out
    return {**base, "fired": False, "condition": None,
            "reason": "all its conditions hold, but it did not fire: " + held_back(plan.attributes, groups_fired)}


def held_back(attributes: dict[str, str], groups_fired: frozenset[str], today: date | None = None) -> str:
    """Why a rule whose conditions hold did not fire, from its attributes: the first that explains
    it (disabled, not yet effective or expired today, its activation group's turn taken), else
    what could have (its agenda group, no-loop/lock-on-active), else the fire limit."""
    today = today or date.today()
    effective, expires = _day(attributes.get("date-effective")), _day(attributes.get("date-expires"))
    group, agenda = attributes.get("activation-group"), attributes.get("agenda-group")
    if attributes.get("enabled") == "false":
        return "it is disabled (enabled false)"
    if effective is not None and effective > today:
        return f"it takes effect on {attributes['date-effective']} (date-effective)"
    if expires is not None and expires <= today:
        return f"it expired on {attributes['date-expires']} (date-expires)"
    if group is not None and group in groups_fired:
        return f'a rule of its activation group "{group}" fired first'
    could = []
    if agenda and agenda != "MAIN" and attributes.get("auto-focus") != "true":
        could.append(f'its agenda group "{agenda}" did not have the focus while they held')
    could += [f"{flag} stopped it" for flag in ("no-loop", "lock-on-active") if attributes.get(flag) == "true"]
    return " or ".join(could) if could else "the fire limit was reached, or its agenda group had no focus"


def _day(text: str | None) -> date | None:
    """A ``date-effective``/``date-expires`` value's day as the engine reads it (its
    ``drools.dateformat``; ``1-Jan-2099`` by default), None if there is none or it is no date."""
    return rule_dates.day(text) if text else None
