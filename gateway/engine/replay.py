"""Replay: fire recorded decisions again on a candidate version and say what would change.

Why: an author who edits a rule sees what the edit does to the cases someone wrote a scenario for,
not to what the gateway really decided yesterday. Every decision is recorded with its facts, the
version, the rules that fired and the actions (:mod:`gateway.store.decisions`), so the candidate
(an undeployed draft, or any stored version) can be fired on each recorded decision's facts and
compared with what was recorded, before anything goes live.

A replay is a dry run through and through: the candidate is compiled on the same path as the
workbench's "try it" (:meth:`Engine.compile_draft`), each decision's facts are fired in a throwaway
stateless session whose ``actions`` global only records what the then-parts ask for (nothing is
sent to a robot), no decision is recorded and nothing live is swapped.

Two kinds of recorded decisions are never compared, and are reported with the reason instead:
decisions whose facts were cut at ``decision_facts_max`` (the facts the rules saw are not all
known), and decisions made in a stateful session (their outcome depended on the session's earlier
facts, which a single decision does not hold).

Comparison is by multiset: the rules that fired (by name, with how often) and the actions (as
canonical JSON). Two runs that fired the same rules and asked for the same actions in another order
are unchanged: the order of equal-salience activations is Drools' business, not the author's.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import orjson

from gateway.engine.errors import EngineError

DEFAULT_LIMIT = 1_000
MAX_LIMIT = 100_000
DEFAULT_MAX_CHANGES = 100
MAX_LISTED = 100  # not-replayable and failed decisions listed (all are counted)
PROGRESS_EVERY = 50  # decisions between two progress reports (a report is also where a job is cancelled)

Progress = Callable[[int, int, str], None]
Fire = Callable[[list[dict[str, Any]]], tuple[list[str], list[dict[str, Any]]]]


def not_replayable(decision: dict[str, Any]) -> str | None:
    """Why ``decision`` cannot be compared on a candidate, or None when it can."""
    facts = decision.get("facts") or []
    count = decision.get("facts_count")
    if isinstance(count, int) and count > len(facts):
        return (f"its facts were cut at decision_facts_max: {len(facts)} of {count} kept, "
                "so the rules' input is not known")
    context = decision.get("context") or {}
    if context.get("session"):
        return (f"it was made in the stateful session {context['session']!r}: its outcome depended on "
                "the session's earlier facts")
    return None


def _canonical(action: Any) -> str:
    return orjson.dumps(action, option=orjson.OPT_SORT_KEYS).decode()


def same_outcome(fired_a: list[str], actions_a: list[Any], fired_b: list[str], actions_b: list[Any]) -> bool:
    """Whether two fires did the same: the same rules as often, the same actions as often."""
    return (Counter(fired_a) == Counter(fired_b)
            and Counter(map(_canonical, actions_a)) == Counter(map(_canonical, actions_b)))


@dataclass
class ReplayReport:
    """What a replay found, accumulated decision by decision."""

    ruleset: str
    candidate: dict[str, Any]
    max_changes: int = DEFAULT_MAX_CHANGES
    replayed: int = 0
    changed: int = 0
    unchanged: int = 0
    failed: int = 0
    before: Counter[str] = field(default_factory=Counter)
    after: Counter[str] = field(default_factory=Counter)
    changes: list[dict[str, Any]] = field(default_factory=list)
    skipped: list[dict[str, Any]] = field(default_factory=list)
    skipped_count: int = 0
    failures: list[dict[str, Any]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def skip(self, decision: dict[str, Any], reason: str) -> None:
        self.skipped_count += 1
        if len(self.skipped) < MAX_LISTED:
            self.skipped.append({"decision_id": decision.get("decision_id"), "at": decision.get("at"),
                                 "reason": reason})

    def fail(self, decision: dict[str, Any], error: EngineError) -> None:
        self.replayed += 1
        self.failed += 1
        if len(self.failures) < MAX_LISTED:
            self.failures.append({"decision_id": decision.get("decision_id"), "at": decision.get("at"),
                                  "error": str(error), "kind": getattr(error, "kind", "engine")})

    def compare(self, decision: dict[str, Any], fired: list[str], actions: list[dict[str, Any]]) -> None:
        """Count one replayed decision: the rules' before/after and whether its outcome changed."""
        self.replayed += 1
        recorded_fired = [str(r) for r in decision.get("fired") or []]
        recorded_actions = list(decision.get("actions") or [])
        self.before.update(recorded_fired)
        self.after.update(fired)
        if same_outcome(recorded_fired, recorded_actions, fired, actions):
            self.unchanged += 1
            return
        self.changed += 1
        if len(self.changes) < self.max_changes:
            self.changes.append({
                "decision_id": decision.get("decision_id"), "at": decision.get("at"),
                "origin": decision.get("origin"),
                "before": {"version": decision.get("version"), "fired": recorded_fired, "actions": recorded_actions},
                "after": {"fired": fired, "actions": actions},
            })

    def to_dict(self) -> dict[str, Any]:
        rules = [{"rule": rule, "before": self.before.get(rule, 0), "after": self.after.get(rule, 0)}
                 for rule in sorted(set(self.before) | set(self.after))]
        out: dict[str, Any] = {
            "ruleset": self.ruleset, "candidate": self.candidate, "replayed": self.replayed,
            "changed": self.changed, "unchanged": self.unchanged, "failed": self.failed, "rules": rules,
            "changes": self.changes, "changes_truncated": self.changed > len(self.changes),
            "not_replayable": self.skipped_count, "not_replayable_decisions": self.skipped,
            "failures": self.failures,
        }
        if self.notes:
            out["note"] = " ".join(self.notes)
        return out


def replay(ruleset: str, candidate: dict[str, Any], fire: Fire, decisions: Iterable[dict[str, Any]], *,
           total: int, max_changes: int = DEFAULT_MAX_CHANGES, on_progress: Progress | None = None) -> ReplayReport:
    """Fire each of ``decisions`` (recorded documents) with ``fire`` and compare.

    ``fire(facts) -> (rule names fired, actions)`` runs the candidate (never records, never acts);
    ``total`` is how many decisions ``decisions`` yields (for progress); ``on_progress(done, total,
    "replay")`` is called every few decisions and may raise to stop the replay (a cancelled job).
    """
    report = ReplayReport(ruleset, candidate, max_changes=max_changes)
    progress = on_progress or (lambda _done, _total, _stage: None)
    progress(0, total, "replay")
    done = 0
    for decision in decisions:
        reason = not_replayable(decision)
        if reason is not None:
            report.skip(decision, reason)
        else:
            try:
                fired, actions = fire(list(decision.get("facts") or []))
            except EngineError as exc:  # the candidate refuses these facts (a field it no longer declares...)
                report.fail(decision, exc)
            else:
                report.compare(decision, fired, actions)
        done += 1
        if done % PROGRESS_EVERY == 0:
            progress(done, total, "replay")
    progress(done, max(total, done), "replay")
    if done == 0:
        report.notes.append("no recorded decision of this rule set matches the selection: nothing was replayed")
    elif report.replayed == 0:
        report.notes.append("none of the selected decisions can be replayed (see not_replayable_decisions)")
    return report


def check_limit(limit: int) -> None:
    """``limit`` is a selection size a replay accepts, else ValueError saying the bounds."""
    if not 1 <= limit <= MAX_LIMIT:
        raise ValueError(f"limit {limit}: must be between 1 and {MAX_LIMIT}")


@dataclass(frozen=True)
class ReplayParams:
    """What a replay request asks: the candidate (``files`` or ``version``) and the selection."""

    files: dict[str, str] | None = None
    version: int | None = None
    since: Any = None  # datetime (aware) or None
    until: Any = None
    origin: str | None = None
    limit: int = DEFAULT_LIMIT
    max_changes: int = DEFAULT_MAX_CHANGES
    role: str | None = None  # whose draft: the rule policy checks it for this role


def run(engine: Any, decisions: Any, ruleset: str, params: ReplayParams,
        on_progress: Progress | None = None) -> dict[str, Any]:
    """The whole replay of ``params`` on rule set ``ruleset``: compile the candidate (422 errors as
    validate, VersionNotFound for an unknown version), select the recorded decisions from
    ``decisions`` (a :class:`gateway.store.decisions.DecisionRecord`), fire and compare.

    Raises ValueError for a limit out of bounds (before anything is compiled or read)."""
    check_limit(params.limit)
    progress = on_progress or (lambda _done, _total, _stage: None)
    label, compiled = engine.replay_candidate(ruleset, files=params.files, version=params.version,
                                              on_progress=progress, role=params.role)
    if not decisions.settle():
        notes = ["the newest decisions of this process may be missing: the Information State did not take them in time"]
    else:
        notes = []
    selection = {"ruleset": ruleset, "since": params.since, "until": params.until, "origin": params.origin}
    matching = decisions.count(**selection)
    total = min(matching, params.limit)
    report = replay(ruleset, label, engine.replay_fire(compiled), decisions.iterate(**selection, limit=params.limit),
                    total=total, max_changes=params.max_changes, on_progress=progress)
    report.notes.extend(notes)
    if matching > params.limit:
        report.notes.append(f"{matching} recorded decisions match the selection: the newest {params.limit} "
                            "were replayed (raise limit, or narrow since/until, for the others)")
    out = report.to_dict()
    out["selected"] = total
    out["matching"] = matching
    return out


def junit_xml(report: dict[str, Any], fail_on_change: bool = False) -> str:
    """JUnit XML of a replay's answer, for CI: one test case per listed changed decision (a
    failure when ``fail_on_change``, else a passed case that says what changed), one per failed
    fire (an error), and one for the unchanged decisions."""
    import xml.etree.ElementTree as ET

    name = f"replay {report.get('ruleset')}"
    changes = report.get("changes") or []
    failures = report.get("failures") or []
    suites = ET.Element("testsuites", name=name, tests=str(len(changes) + len(failures) + 1),
                        failures=str(report.get("changed", 0) if fail_on_change else 0),
                        errors=str(report.get("failed", 0)))
    suite = ET.SubElement(suites, "testsuite", name=name, tests=str(len(changes) + len(failures) + 1),
                          failures=str(len(changes) if fail_on_change else 0), errors=str(len(failures)))
    classname = f"replay.{report.get('ruleset')}"
    for change in changes:
        case = ET.SubElement(suite, "testcase", name=f"decision {change['decision_id']} ({change.get('at')})",
                             classname=classname)
        detail = (f"before (v{change['before'].get('version')}): fired {change['before']['fired']}, "
                  f"actions {orjson.dumps(change['before']['actions']).decode()}\n"
                  f"after: fired {change['after']['fired']}, actions {orjson.dumps(change['after']['actions']).decode()}")
        if fail_on_change:
            ET.SubElement(case, "failure", message="the candidate decides differently", type="changed").text = detail
        else:
            ET.SubElement(case, "system-out").text = detail
    for failure in failures:
        case = ET.SubElement(suite, "testcase", name=f"decision {failure['decision_id']}", classname=classname)
        ET.SubElement(case, "error", message=failure["error"], type=str(failure.get("kind")))
    ET.SubElement(suite, "testcase", name=f"{report.get('unchanged', 0)} decisions unchanged", classname=classname)
    return ET.tostring(suites, encoding="unicode", xml_declaration=True)


def text_table(report: dict[str, Any]) -> list[str]:
    """The summary a terminal shows: counts, then rule | before | after (changed rules marked)."""
    lines = [f"replayed {report.get('replayed', 0)} decisions of {report.get('ruleset')} on "
             + ", ".join(f"{k} {v}" for k, v in (report.get("candidate") or {}).items())
             + f": {report.get('changed', 0)} changed, {report.get('unchanged', 0)} unchanged, "
               f"{report.get('failed', 0)} failed, {report.get('not_replayable', 0)} not replayable"]
    if report.get("note"):
        lines.append(f"note: {report['note']}")
    rules = report.get("rules") or []
    if rules:
        width = max(4, *(len(r["rule"]) for r in rules))
        lines.append(f"{'rule'.ljust(width)}  {'before':>7}  {'after':>7}")
        for r in rules:
            mark = "  *" if r["before"] != r["after"] else ""
            lines.append(f"{r['rule'].ljust(width)}  {r['before']:>7}  {r['after']:>7}{mark}")
    for change in report.get("changes") or []:
        lines.append(f"changed {change['decision_id']} at {change.get('at')}: "
                     f"{change['before']['fired']} -> {change['after']['fired']}")
    if report.get("changes_truncated"):
        lines.append(f"... {report['changed'] - len(report.get('changes') or [])} more changed decisions not listed")
    return lines
