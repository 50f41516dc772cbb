"""Update the tests too: rewrite the expectations a draft's changed sentence or value broke.

Why: an owner who changes what Pepper says ("Welcome. Two seats?" → "Welcome! A table for two?")
meant the change; the scenarios that pin the old sentence then block the deploy for no reason the
owner would recognise. This module finds the scenarios that fail *only* because they still name something the draft
changed — a value in an expected action or fact, or the name of a renamed rule — and rewrites it in
the ``tests/*.yaml`` text at its line — comments, order and layout untouched (the YAML is never
re-dumped).

A scenario is rewritten only when all of this holds:

* it ran and failed (a scenario whose facts were refused or whose firing failed is left alone);
* each expected action it misses has an actual action of the same module (from a rule) whose
  params differ only in plain values, each old value no longer in the draft's rule sources and
  each new value in them, and the old value in the live version's sources (the draft changed it;
  with no live version there is nothing a draft could have changed);
* each expected fact it misses has an actual fact of the same type that differs from it in the
  same way (only in values the draft changed);
* each rule it names (``fired``, ``not_fired``) that the draft no longer has was renamed, and
  unambiguously: the live version had it, and either it is the only rule gone and exactly one new
  rule came (the classic rename), or exactly one new rule has the same text after its name;
* after the rewrite, the scenario — compared again with what actually happened — passes.

Anything else (a rule that no longer fires, a missing fact, an extra action…) keeps it red and
untouched. Nothing is stored: the caller gets the updated files and the list of changes.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from typing import Any

import yaml

from gateway.engine import decision_table
from gateway.engine.ruleset import is_table_file, is_test_file
from gateway.engine.scenario_files import parse_file
from gateway.engine.scenarios import (
    ScenarioResult, _Engine, _equal, _match_actions, _subset, compare, run_scenarios,
)

SCAN_LINES = 20  # how far below an expected action's first line its params may stand (block style)


@dataclass
class Change:
    """One value rewritten in a test file."""

    scenario: str
    file: str
    line: int
    old: Any
    new: Any
    rule: str | None = None
    #: "action": a param of an expected action; "fact": a field of an expected fact; "rule": a rule's name
    what: str = "action"

    def to_dict(self) -> dict[str, Any]:
        return {"scenario": self.scenario, "file": self.file, "line": self.line, "old": self.old,
                "new": self.new, "rule": self.rule, "what": self.what}


def rule_sources(files: dict[str, str]) -> str:
    """The text in which the rules' sentences and values are written: the rule files without their
    comments (a comment listing the old value must not make it look still in use), decision tables
    as the DRL they become."""
    parts = []
    for name, text in files.items():
        if is_test_file(name) or name.endswith(".json"):
            continue
        if is_table_file(name):
            parts.append(decision_table.convert(name, text).drl or "")
        else:
            parts.append(without_comments(text))
    return "\n".join(parts)


_CODE_OR_COMMENT = re.compile(r'"(?:[^"\\\n]|\\.)*"|\'(?:[^\'\\\n]|\\.)*\'|//[^\n]*|/\*.*?\*/|^[ \t]*#[^\n]*',
                              re.DOTALL | re.MULTILINE)


def without_comments(text: str) -> str:
    """``text`` with its ``//``, ``/* */`` and whole-line ``#`` comments blanked (quoted text kept;
    line numbers kept)."""
    def blank(match: re.Match[str]) -> str:
        token = match.group()
        if token[0] in "\"'":
            return token
        return re.sub(r"[^\n]", " ", token)
    return _CODE_OR_COMMENT.sub(blank, text)


def _mentions(source: str, value: Any) -> bool:
    if isinstance(value, bool) or value is None:
        return False
    if isinstance(value, str):  # a whole literal: quoted, or the rest of its line ("moves to the table for two")
        if not value:
            return False
        quoted = '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
        whole = re.compile(rf"(?<![\w]){re.escape(value)}\s*$", re.MULTILINE)
        return quoted in source or whole.search(source) is not None
    return re.search(rf"(?<![\w.]){re.escape(str(value))}(?![\w.])", source) is not None


def update_tests(engine: _Engine, files: dict[str, str], ruleset: str = "draft",
                 base_files: dict[str, str] | None = None) -> dict[str, Any]:
    """``{"files": {test file: updated text}, "changes": [...], "kept": [scenario names still red]}``
    for the draft ``files``; ``base_files`` are the live version's (None: no version is live, so
    nothing is rewritten).
    Raises CompileFailed as the test run does when the draft does not compile."""
    report = run_scenarios(engine, files, ruleset)
    draft_src = rule_sources(files)
    base_src = rule_sources(base_files) if base_files is not None else None
    renamed = renames(base_src, draft_src, list(report.rules)) if base_src is not None else {}
    texts = {name: files[name] for name in files if is_test_file(name)}
    changes: list[Change] = []
    kept: list[str] = []
    for result in report.red():
        found = _rewrite(result, texts, draft_src, base_src, list(report.rules), renamed)
        if found is None:
            kept.append(result.scenario.name)
            continue
        new_text, scenario_changes = found
        texts[result.scenario.file] = new_text
        changes.extend(scenario_changes)
    updated = {name: text for name, text in texts.items() if text != files[name]}
    return {"files": updated, "changes": [c.to_dict() for c in changes], "kept": kept}


def _rewrite(result: ScenarioResult, texts: dict[str, str], draft_src: str, base_src: str | None,
             rule_names: list[str], renamed: dict[str, str]) -> tuple[str, list[Change]] | None:
    """The scenario's file with its stale names and values rewritten, and the changes; None: not
    only a changed value or a renamed rule makes it fail."""
    if result.status != "failed" or "actions" not in result.actual:
        return None
    scenario = result.scenario
    text = texts[scenario.file]
    changes: list[Change] = []
    for step in (_rename_rules, _rewrite_actions, _rewrite_facts):
        done = step(result, text, draft_src, base_src, rule_names, renamed)
        if done is None:
            return None
        text, more = done
        changes.extend(more)
    if not changes or not _passes_now(result, text, rule_names):
        return None
    return text, changes


_Step = tuple[str, list[Change]] | None


def _rename_rules(result: ScenarioResult, text: str, draft_src: str, base_src: str | None, rule_names: list[str],
                  renamed: dict[str, str]) -> _Step:
    """Each rule named in ``fired``/``not_fired`` that the draft renamed, under its new name."""
    scenario = result.scenario
    expect = scenario.expect
    changes: list[Change] = []
    for key, names in (("fired", list(expect.fired)), ("not_fired", expect.not_fired)):
        for name in names:
            if name in rule_names:
                continue
            new = renamed.get(name)
            line = expect.lines.get(f"{key}:{name}")
            edited = _edit_name(text, line, name, new) if new is not None and line is not None else None
            if edited is None:
                return None
            text = edited
            changes.append(Change(scenario.name, scenario.file, line, name, new, new, "rule"))
    return text, changes


def _rewrite_actions(result: ScenarioResult, text: str, draft_src: str, base_src: str | None, rule_names: list[str],
                     renamed: dict[str, str]) -> _Step:
    """Each expected action that was not requested, with the values the draft changed."""
    scenario = result.scenario
    actual = result.actual["actions"]
    expected = scenario.expect.actions
    matched = _match_actions(expected, actual, scenario.expect.ordered)
    free = [k for k in range(len(actual)) if k not in set(matched.values())]
    changes: list[Change] = []
    for i, wanted in enumerate(expected):
        if i in matched:
            continue
        candidates = [actual[k] for k in free]
        eligible = [(a.get("params") or {}) if a.get("module") == wanted.module and a.get("rule") else None
                    for a in candidates]
        pick = _first_changed(wanted.params, eligible, draft_src, base_src)
        if pick is None:
            return None
        index, diffs = pick
        rule = candidates[index].get("rule")
        free.pop(index)
        for key, (old, new) in diffs.items():
            edited = _edit_value(text, wanted.line, key, old, new)
            if edited is None:
                return None
            text, line = edited
            changes.append(Change(scenario.name, scenario.file, line, old, new, rule))
    return text, changes


def _rewrite_facts(result: ScenarioResult, text: str, draft_src: str, base_src: str | None, rule_names: list[str],
                   renamed: dict[str, str]) -> _Step:
    """Each expected fact that no actual fact matches, with the values the draft changed (matched
    greedily in file order, as :func:`compare` does)."""
    scenario = result.scenario
    facts = result.actual.get("facts") or []
    taken: set[int] = set()
    missing: list[tuple[dict[str, Any], int]] = []
    for wanted, line in scenario.expect.facts:
        index = next((k for k, fact in enumerate(facts) if k not in taken and _subset(wanted, fact)), None)
        if index is None:
            missing.append((wanted, line))
        else:
            taken.add(index)
    changes: list[Change] = []
    for wanted, line in missing:
        free = [k for k in range(len(facts)) if k not in taken]
        pick = _first_changed(wanted, [facts[k] if facts[k].get("type") == wanted.get("type") else None for k in free],
                              draft_src, base_src)
        if pick is None:
            return None
        index, diffs = pick
        taken.add(free[index])
        for key, (old, new) in diffs.items():
            edited = _edit_value(text, line, key, old, new)
            if edited is None:
                return None
            text, at = edited
            changes.append(Change(scenario.name, scenario.file, at, old, new, None, "fact"))
    return text, changes


def _first_changed(wanted: dict[str, Any], candidates: list[dict[str, Any] | None], draft_src: str,
                   base_src: str | None) -> tuple[int, dict[str, tuple[Any, Any]]] | None:
    """The first candidate (None: not eligible) that differs from ``wanted`` only in values the
    draft changed: its index in ``candidates`` and ``{key: (old, new)}``."""
    for index, got in enumerate(candidates):
        if got is None:
            continue
        diffs: dict[str, tuple[Any, Any]] | None = {}
        for key, old in wanted.items():
            if _equal(old, got.get(key)):
                continue
            new = got.get(key)
            if not _is_changed_value(old, new, draft_src, base_src):
                diffs = None
                break
            diffs[key] = (old, new)
        if diffs:
            return index, diffs
    return None


def _is_changed_value(old: Any, new: Any, draft_src: str, base_src: str | None) -> bool:
    scalar = (str, int, float)
    if not isinstance(old, scalar) or not isinstance(new, scalar) or isinstance(old, bool) or isinstance(new, bool):
        return False
    if _mentions(draft_src, old) or not _mentions(draft_src, new):
        return False
    return base_src is not None and _mentions(base_src, old)


# --------------------------------------------------------------------------- renamed rules

_RULE_HEAD = re.compile(r"""^[ \t]*rule[ \t]+(?:"((?:[^"\\]|\\.)*)"|'([^']*)'|([^\s"']+))""", re.MULTILINE)
_RULE_END = re.compile(r"^[ \t]*end[ \t]*$", re.MULTILINE)


def rule_texts(source: str) -> dict[str, str]:
    """Each rule declared in ``source`` (DRL, DSLR, a table's DRL): its name -> the text after the
    name up to its ``end``, whitespace folded (to recognise a rule that only changed its name)."""
    out: dict[str, str] = {}
    for match in _RULE_HEAD.finditer(source):
        name = next(g for g in match.groups() if g is not None)
        end = _RULE_END.search(source, match.end())
        body = source[match.end():end.start() if end else len(source)]
        out.setdefault(name, " ".join(body.split()))
    return out


def renames(base_src: str, draft_src: str, draft_rules: list[str]) -> dict[str, str]:
    """``{old name: new name}`` for the rules the draft renamed, only where that is unambiguous:
    one rule gone and one new rule (whatever else changed), or else one new rule with exactly the
    same text as the gone one (and no other gone rule with that text)."""
    base = rule_texts(base_src)
    draft = rule_texts(draft_src)
    present = set(draft_rules)
    gone = [name for name in base if name not in present]
    new = [name for name in draft_rules if name not in base]
    if len(gone) == 1 and len(new) == 1:
        return {gone[0]: new[0]}
    out: dict[str, str] = {}
    for old in gone:
        same = [name for name in new if draft.get(name) == base[old]]
        twins = [other for other in gone if base[other] == base[old]]
        if len(same) == 1 and len(twins) == 1:
            out[old] = same[0]
    return out


# --------------------------------------------------------------------------- editing the YAML text


def _spellings(value: Any) -> list[tuple[str, str]]:
    """How ``value`` may be written in YAML, with its style: double-quoted, single-quoted, plain."""
    if isinstance(value, str):
        return [("double", json.dumps(value, ensure_ascii=False)), ("single", "'" + value.replace("'", "''") + "'"),
                ("plain", value)]
    return [("plain", str(value))]


def _spell(value: Any, style: str) -> str:
    if not isinstance(value, str):
        return str(value)
    if style == "single":
        return "'" + value.replace("'", "''") + "'"
    if style == "plain" and re.fullmatch(r"[A-Za-z][\w .-]*", value) and yaml.safe_load(value) == value:
        return value
    return json.dumps(value, ensure_ascii=False)


def _edit_value(text: str, line: int, key: str, old: Any, new: Any) -> tuple[str, int] | None:
    """``text`` with ``key: old`` at or below ``line`` (1-based) rewritten to ``key: new`` in the
    same quoting style, and the line it stands on."""
    lines = text.split("\n")
    for n in range(line - 1, min(len(lines), line - 1 + SCAN_LINES)):
        for style, spelt in _spellings(old):
            tail = r"(?=\s*[,}\n#]|\s*$)" if style == "plain" else ""
            pattern = re.compile(rf"(\b{re.escape(str(key))}\s*:\s*){re.escape(spelt)}{tail}")
            match = pattern.search(lines[n])
            if match:
                lines[n] = lines[n][:match.start()] + match.group(1) + _spell(new, style) + lines[n][match.end():]
                return "\n".join(lines), n + 1
    return None


def _edit_name(text: str, line: int, old: str, new: str) -> str | None:
    """``text`` with the rule name ``old`` on ``line`` (1-based; a list item, a flow list's entry or
    a count's key) rewritten to ``new`` in the same quoting style."""
    lines = text.split("\n")
    if not 1 <= line <= len(lines):
        return None
    for style, spelt in _spellings(old):
        if style == "plain":
            pattern = re.compile(rf"(?<![^\[{{,\s]){re.escape(spelt)}(?=\s*(?:[,:\]}}#]|$))")
        else:
            pattern = re.compile(re.escape(spelt))
        match = pattern.search(lines[line - 1])
        if match:
            row = lines[line - 1]
            lines[line - 1] = row[:match.start()] + _spell(new, style) + row[match.end():]
            return "\n".join(lines)
    return None


def _passes_now(result: ScenarioResult, text: str, rule_names: list[str]) -> bool:
    """The scenario, parsed again from the rewritten text, compared with what actually happened."""
    scenarios, errors = parse_file(result.scenario.file, text)
    if errors:
        return False
    again = next((s for s in scenarios if s.name == result.scenario.name), None)
    if again is None:
        return False
    actual = result.actual
    return not compare(again, actual["fired"], actual["actions"], actual["facts"], rule_names)
