"""Update the tests too: rewrite the expectations a draft's changed sentence or value broke.

Why: an owner who changes what Pepper says ("Welcome. Two seats?" → "Welcome! A table for two?")
meant the change; the scenarios that pin the old sentence then block the deploy for no reason the
owner would recognise. This module finds the scenarios that fail *only* because an expected action
still names a value the draft no longer has, and rewrites that value in the ``tests/*.yaml`` text at
its line — comments, order and layout untouched (the YAML is never re-dumped).

A scenario is rewritten only when all of this holds:

* it ran and failed (a scenario whose facts were refused or whose firing failed is left alone);
* each expected action it misses has an actual action of the same module (from a rule) whose
  params differ only in plain values, each old value no longer in the draft's rule sources and
  each new value in them, and the old value in the live version's sources (the draft changed it;
  with no live version there is nothing a draft could have changed);
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
from gateway.engine.scenarios import ScenarioResult, _Engine, _equal, _match_actions, compare, run_scenarios

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

    def to_dict(self) -> dict[str, Any]:
        return {"scenario": self.scenario, "file": self.file, "line": self.line, "old": self.old,
                "new": self.new, "rule": self.rule}


def rule_sources(files: dict[str, str]) -> str:
    """The text in which the rules' sentences and values are written: the rule files as they are,
    decision tables as the DRL they become."""
    parts = []
    for name, text in files.items():
        if is_test_file(name) or name.endswith(".json"):
            continue
        if is_table_file(name):
            parts.append(decision_table.convert(name, text).drl or "")
        else:
            parts.append(text)
    return "\n".join(parts)


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
    texts = {name: files[name] for name in files if is_test_file(name)}
    changes: list[Change] = []
    kept: list[str] = []
    for result in report.red():
        found = _rewrite(result, texts, draft_src, base_src, list(report.rules))
        if found is None:
            kept.append(result.scenario.name)
            continue
        new_text, scenario_changes = found
        texts[result.scenario.file] = new_text
        changes.extend(scenario_changes)
    updated = {name: text for name, text in texts.items() if text != files[name]}
    return {"files": updated, "changes": [c.to_dict() for c in changes], "kept": kept}


def _rewrite(result: ScenarioResult, texts: dict[str, str], draft_src: str, base_src: str | None,
             rule_names: list[str]) -> tuple[str, list[Change]] | None:
    """The scenario's file with its stale values rewritten, and the changes; None: not only a
    changed value makes it fail."""
    if result.status != "failed" or "actions" not in result.actual:
        return None
    scenario = result.scenario
    actual = result.actual["actions"]
    expected = scenario.expect.actions
    matched = _match_actions(expected, actual, scenario.expect.ordered)
    free = [k for k in range(len(actual)) if k not in set(matched.values())]
    text = texts[scenario.file]
    changes: list[Change] = []
    for i, wanted in enumerate(expected):
        if i in matched:
            continue
        pick = _changed_values(wanted.module, wanted.params, [actual[k] for k in free], draft_src, base_src)
        if pick is None:
            return None
        index, diffs = pick
        rule = actual[free[index]].get("rule")
        free.pop(index)
        for key, (old, new) in diffs.items():
            edited = _edit_value(text, wanted.line, key, old, new)
            if edited is None:
                return None
            text, line = edited
            changes.append(Change(scenario.name, scenario.file, line, old, new, rule))
    if not changes or not _passes_now(result, text, rule_names):
        return None
    return text, changes


def _changed_values(module: str, params: dict[str, Any], candidates: list[dict[str, Any]], draft_src: str,
                    base_src: str | None) -> tuple[int, dict[str, tuple[Any, Any]]] | None:
    """The first actual action that differs from the expected one only in values the draft changed:
    its index in ``candidates`` and ``{param: (old, new)}``."""
    for index, action in enumerate(candidates):
        if action.get("module") != module or not action.get("rule"):
            continue
        got = action.get("params") or {}
        diffs: dict[str, tuple[Any, Any]] = {}
        for key, old in params.items():
            if _equal(old, got.get(key)):
                continue
            new = got.get(key)
            if not _is_changed_value(old, new, draft_src, base_src):
                diffs = {}
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
