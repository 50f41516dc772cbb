"""Rule test scenario files (``tests/*.yaml`` of a rule set): their model and their parser.

Why apart from the runner (:mod:`gateway.engine.scenarios`): the compiler refuses a rule set whose
scenario files are malformed (:func:`format_errors`), and the runner compiles the rule set it
tests; with the parser here, neither module needs the other's. The format is described in
:mod:`gateway.engine.scenarios`.

Plain Python: a malformed file gets :class:`CompileError` objects naming the file, line and column.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from typing import Any

import yaml

from gateway.engine.errors import CompileError
from gateway.engine.ruleset import is_test_file

SCENARIO_KEYS = ("name", "description", "given", "expect")
EXPECT_KEYS = ("fired", "not_fired", "actions", "no_other_actions", "ordered", "facts")


# --------------------------------------------------------------------------- YAML with positions


class _Mapping(dict):
    """A YAML mapping that remembers where it and each of its values stand."""

    where: tuple[int, int] = (0, 0)
    positions: dict[Any, tuple[int, int]]  # of each value
    key_positions: dict[Any, tuple[int, int]]


class _Sequence(list):
    where: tuple[int, int] = (0, 0)
    positions: list[tuple[int, int]]


def _pos(node: yaml.Node) -> tuple[int, int]:
    return node.start_mark.line + 1, node.start_mark.column + 1


class _Loader(yaml.SafeLoader):
    """SafeLoader whose mappings and lists know their lines (and which refuses duplicate keys)."""


def _construct_mapping(loader: _Loader, node: yaml.MappingNode) -> _Mapping:
    loader.flatten_mapping(node)
    out = _Mapping()
    out.where, out.positions, out.key_positions = _pos(node), {}, {}
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=True)
        try:
            hash(key)
        except TypeError:
            raise yaml.constructor.ConstructorError(None, None, "a key must be a plain value", key_node.start_mark)
        if key in out:
            raise yaml.constructor.ConstructorError(None, None, f"duplicate key {key!r}", key_node.start_mark)
        out[key] = loader.construct_object(value_node, deep=True)
        out.positions[key] = _pos(value_node)
        out.key_positions[key] = _pos(key_node)
    return out


def _construct_sequence(loader: _Loader, node: yaml.SequenceNode) -> _Sequence:
    out = _Sequence(loader.construct_object(child, deep=True) for child in node.value)
    out.where, out.positions = _pos(node), [_pos(child) for child in node.value]
    return out


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_mapping)
_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, _construct_sequence)


def _plain(value: Any) -> Any:
    """Without the position bookkeeping: plain dicts and lists (as facts and JSON want them)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value


# --------------------------------------------------------------------------- the model


@dataclass
class ExpectedAction:
    module: str
    params: dict[str, Any]
    line: int

    def to_dict(self) -> dict[str, Any]:
        return {"module": self.module, "params": self.params}


@dataclass
class Expectation:
    fired: dict[str, int | None] = field(default_factory=dict)  # rule -> exact count, None: at least once
    not_fired: list[str] = field(default_factory=list)
    actions: list[ExpectedAction] = field(default_factory=list)
    no_other_actions: bool = False
    ordered: bool = False
    facts: list[tuple[dict[str, Any], int]] = field(default_factory=list)
    lines: dict[str, int] = field(default_factory=dict)  # "fired:Greet a pair" / "not_fired:X" -> line


@dataclass
class Scenario:
    file: str
    line: int
    name: str
    given: list[dict[str, Any]]
    given_lines: list[int]
    expect: Expectation
    raw_expect: dict[str, Any]
    description: str = ""


# --------------------------------------------------------------------------- parsing


class _Problems:
    def __init__(self, file: str):
        self.file = file
        self.errors: list[CompileError] = []

    def add(self, where: tuple[int, int], message: str) -> None:
        self.errors.append(CompileError(self.file, where[0], where[1], message))


def did_you_mean(word: str, options: tuple[str, ...] | list[str]) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``options`` to ``word`` (or ''): the runner names rules so too."""
    close = difflib.get_close_matches(str(word), list(options), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _unknown_keys(mapping: _Mapping, allowed: tuple[str, ...], what: str, problems: _Problems) -> None:
    for key in mapping:
        if key not in allowed:
            problems.add(mapping.key_positions[key], f"unknown key {key!r} in {what}{did_you_mean(key, allowed)}; "
                                                 f"allowed: {', '.join(allowed)}")


def parse_file(file_name: str, text: str) -> tuple[list[Scenario], list[CompileError]]:
    """The scenarios of one ``tests/*.yaml`` text, or the problems that make it unusable."""
    problems = _Problems(file_name)
    try:
        data = yaml.load(text, Loader=_Loader)  # noqa: S506 - _Loader is a SafeLoader
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
        line, col = (mark.line + 1, mark.column + 1) if mark is not None else (0, 0)
        detail = " ".join(str(p) for p in (getattr(exc, "context", None), getattr(exc, "problem", None)) if p) or str(exc)
        return [], [CompileError(file_name, line, col, f"not valid YAML: {detail}")]
    if data is None:
        return [], []
    if not isinstance(data, list):
        where = getattr(data, "where", (1, 1))
        return [], [CompileError(file_name, where[0], where[1],
                                 "a scenario file is a list of scenarios: each starts with '- name: …'")]
    scenarios: list[Scenario] = []
    for index, item in enumerate(data):
        where = data.positions[index]
        if not isinstance(item, dict):
            problems.add(where, f"scenario {index + 1} must be a mapping with name, given and expect")
            continue
        scenario = _parse_scenario(file_name, item, where, problems)
        if scenario is not None:
            scenarios.append(scenario)
    return scenarios, problems.errors


def _parse_scenario(file_name: str, item: _Mapping, where: tuple[int, int], problems: _Problems) -> Scenario | None:
    before = len(problems.errors)
    _unknown_keys(item, SCENARIO_KEYS, "a scenario", problems)
    name = item.get("name")
    if not isinstance(name, str) or not name.strip():
        problems.add(item.positions.get("name", where), "a scenario needs a 'name' (text)")
        name = ""
    description = item.get("description", "")
    if not isinstance(description, str):
        problems.add(item.positions["description"], "'description' must be text")
    given = item.get("given", [])
    given_lines: list[int] = []
    if given is None:
        given = []
    if not isinstance(given, list):
        problems.add(item.positions.get("given", where), "'given' must be a list of facts ({type: …, field: value})")
        given = []
    else:
        for i, fact in enumerate(given):
            fact_where = given.positions[i]
            given_lines.append(fact_where[0])
            if not isinstance(fact, dict) or not isinstance(fact.get("type"), str) or not fact.get("type"):
                problems.add(fact_where, f"fact {i + 1} of 'given' must be a mapping with a 'type' "
                                         "(e.g. {type: Customer, id: c1, age: 6})")
    if "expect" not in item:
        problems.add(where, f"scenario {name!r} has no 'expect': say what must happen")
        return None
    expect = _parse_expect(item["expect"], item.positions["expect"], problems)
    if len(problems.errors) > before or expect is None:
        return None
    return Scenario(file_name, where[0], name.strip(), _plain(given), given_lines, expect,
                    _plain(item["expect"]), description or "")


def _rule_names(value: Any, key: str, where: tuple[int, int], problems: _Problems) -> list[tuple[str, int, tuple[int, int]]]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list):
        problems.add(where, f"'{key}' must be a list of rule names")
        return []
    out = []
    for i, name in enumerate(value):
        pos = value.positions[i] if isinstance(value, _Sequence) else where
        if not isinstance(name, str) or not name.strip():
            problems.add(pos, f"'{key}' item {i + 1} must be a rule name (text)")
            continue
        out.append((name.strip(), pos[0], pos))
    return out


def _parse_expect(expect: Any, where: tuple[int, int], problems: _Problems) -> Expectation | None:
    if not isinstance(expect, dict):
        problems.add(where, "'expect' must be a mapping (fired, not_fired, actions, no_other_actions, facts)")
        return None
    _unknown_keys(expect, EXPECT_KEYS, "'expect'", problems)
    if not any(k in expect for k in ("fired", "not_fired", "actions", "facts")) and not expect.get("no_other_actions"):
        problems.add(where, "'expect' is empty: list the rules that fire, the actions or the facts that must follow")
    out = Expectation()
    fired = expect.get("fired")
    if isinstance(fired, dict):
        for name, count in fired.items():
            pos = fired.positions[name]
            if not isinstance(count, int) or isinstance(count, bool) or count < 0:
                problems.add(pos, f"'fired': the count for {name!r} must be a whole number ≥ 0")
                continue
            out.fired[str(name)] = count
            out.lines[f"fired:{name}"] = pos[0]
    elif fired is not None:
        for name, line, _ in _rule_names(fired, "fired", expect.positions["fired"], problems):
            out.fired[name] = None
            out.lines[f"fired:{name}"] = line
    if expect.get("not_fired") is not None:
        for name, line, pos in _rule_names(expect["not_fired"], "not_fired", expect.positions["not_fired"], problems):
            if name in out.fired:
                problems.add(pos, f"{name!r} is in both 'fired' and 'not_fired'")
            out.not_fired.append(name)
            out.lines[f"not_fired:{name}"] = line
    actions = expect.get("actions")
    if actions is not None:
        if not isinstance(actions, list):
            problems.add(expect.positions["actions"], "'actions' must be a list of {module: …, params: {…}}")
        else:
            for i, action in enumerate(actions):
                pos = actions.positions[i]
                if not isinstance(action, dict) or not isinstance(action.get("module"), str):
                    problems.add(pos, f"action {i + 1} must be a mapping with a 'module' (say, move, gesture, …)")
                    continue
                _unknown_keys(action, ("module", "params"), f"action {i + 1}", problems)
                params = action.get("params", {}) or {}
                if not isinstance(params, dict):
                    problems.add(action.positions["params"], f"action {i + 1}: 'params' must be a mapping")
                    continue
                out.actions.append(ExpectedAction(action["module"], _plain(params), pos[0]))
    for flag in ("no_other_actions", "ordered"):
        if flag in expect:
            if not isinstance(expect[flag], bool):
                problems.add(expect.positions[flag], f"'{flag}' must be true or false")
            else:
                setattr(out, flag, expect[flag])
    facts = expect.get("facts")
    if facts is not None:
        if not isinstance(facts, list):
            problems.add(expect.positions["facts"], "'facts' must be a list of {type: …, field: value}")
        else:
            for i, fact in enumerate(facts):
                pos = facts.positions[i]
                if not isinstance(fact, dict) or not isinstance(fact.get("type"), str):
                    problems.add(pos, f"expected fact {i + 1} must be a mapping with a 'type'")
                    continue
                out.facts.append((_plain(fact), pos[0]))
    return out


def parse_files(files: dict[str, str]) -> tuple[list[Scenario], list[CompileError]]:
    """Every scenario of a rule set's ``tests/*.yaml`` files (in file order), and all problems;
    scenario names must be unique across the files."""
    scenarios: list[Scenario] = []
    errors: list[CompileError] = []
    seen: dict[str, Scenario] = {}
    for file_name in sorted(f for f in files if is_test_file(f)):
        found, problems = parse_file(file_name, files[file_name])
        errors.extend(problems)
        for scenario in found:
            first = seen.get(scenario.name)
            if first is not None:
                errors.append(CompileError(file_name, scenario.line, 1,
                                           f"a second scenario named {scenario.name!r} (the first is at "
                                           f"{first.file}:{first.line}): names must be unique"))
                continue
            seen[scenario.name] = scenario
            scenarios.append(scenario)
    return scenarios, errors


def format_errors(files: dict[str, str]) -> list[CompileError]:
    """The problems of the rule set's scenario files ([] when they are well-formed)."""
    if not any(is_test_file(f) for f in files):
        return []
    return parse_files(files)[1]
