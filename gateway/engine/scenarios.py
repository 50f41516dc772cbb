"""Rule test scenarios: "given these facts, these rules fire and the robot does this".

Why: a rule set changes while the robots run; its scenarios say what must keep happening, so a
deploy can be refused before it silently breaks a greeting (Business Central's test scenarios, in a
file format an owner can read). Scenarios are kept and versioned with the rule set as
``tests/*.yaml`` in its folder (and in ``files`` over REST)::

    - name: family of three gets the child greeting
      given:                      # facts, as for /fire
        - {type: Customer, id: c1, age: 6}
      expect:
        fired: [Greet child]      # these rules fired (at least once); or {Greet child: 1} for a count
        not_fired: [Greet adult]
        actions:                  # each expected action matches one action (params: a subset)
          - {module: say, params: {robot: pepper, text: "Hello little one"}}
        no_other_actions: false   # true: no action beyond those listed
        ordered: false            # true: the listed actions come in this order
        facts:                    # facts after firing; each matches one fact (fields: a subset)
          - {type: Customer, id: c1, category: child}

Plain Python: a malformed file gets :class:`CompileError` objects naming the file, line and column
(:func:`format_errors`, which the compiler also reports, so nothing with a broken scenario file
deploys); :func:`run_scenarios` fires each scenario through the engine on the compiled rule set
(one build for all of them) and compares; the :class:`TestReport` gives the expected and actual of
every scenario, the rules no scenario fires (coverage) and JUnit XML for CI.
"""

from __future__ import annotations

import difflib
import re
import time
import xml.etree.ElementTree as ET
from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Protocol

import yaml

from gateway.engine.errors import CompileError, CompileFailed, EngineError, FactError
from gateway.engine.ruleset import is_test_file

SCENARIO_KEYS = ("name", "description", "given", "expect")
EXPECT_KEYS = ("fired", "not_fired", "actions", "no_other_actions", "ordered", "facts")


class _Engine(Protocol):  # what the runner needs of gateway.engine.Engine
    def fire_files(self, files: dict[str, str], facts: list[dict[str, Any]], fire_limit: int | None = None) -> Any: ...

    def check_policy(self, name: str, files: dict[str, str], role: str | None) -> None: ...


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


@dataclass
class Failure:
    message: str
    line: int

    def to_dict(self) -> dict[str, Any]:
        return {"message": self.message, "line": self.line}


@dataclass
class ScenarioResult:
    scenario: Scenario
    status: str  # "passed" | "failed" | "error"
    failures: list[Failure] = field(default_factory=list)
    actual: dict[str, Any] = field(default_factory=dict)
    duration_ms: float = 0.0

    @property
    def passed(self) -> bool:
        return self.status == "passed"

    def to_dict(self) -> dict[str, Any]:
        sc = self.scenario
        return {
            "name": sc.name,
            "file": sc.file,
            "line": sc.line,
            "description": sc.description,
            "status": self.status,
            "failures": [f.to_dict() for f in self.failures],
            "given": sc.given,
            "expected": sc.raw_expect,
            "actual": self.actual,
            "duration_ms": round(self.duration_ms, 3),
        }


@dataclass
class TestReport:
    """The outcome of a rule set's scenarios, with coverage."""

    __test__ = False  # not a pytest class

    ruleset: str
    version: int | None
    results: list[ScenarioResult]
    rules: list[str]
    files: list[str]

    @property
    def counts(self) -> dict[str, int]:
        c = Counter(r.status for r in self.results)
        return {"scenarios": len(self.results), "passed": c["passed"], "failed": c["failed"], "errors": c["error"]}

    @property
    def ok(self) -> bool:
        return all(r.passed for r in self.results)

    @property
    def fired_rules(self) -> list[str]:
        fired = {name for r in self.results for name in r.actual.get("fired", [])}
        return [name for name in self.rules if name in fired]

    @property
    def uncovered(self) -> list[str]:
        """Rules that no scenario fires."""
        fired = set(self.fired_rules)
        return [name for name in self.rules if name not in fired]

    def red(self) -> list[ScenarioResult]:
        return [r for r in self.results if not r.passed]

    def problems(self) -> list[CompileError]:
        """Each failure as a problem at its scenario file and line (for editors and the CLI)."""
        out = []
        for result in self.red():
            for failure in result.failures:
                out.append(CompileError(result.scenario.file, failure.line, 1,
                                        f"scenario '{result.scenario.name}': {failure.message}"))
        return out

    def summary(self) -> str:
        c = self.counts
        if not c["scenarios"]:
            return "no scenarios (add tests/*.yaml to the rule set)"
        red = c["failed"] + c["errors"]
        text = f"{c['scenarios']} scenarios: {c['passed']} passed"
        if c["failed"]:
            text += f", {c['failed']} failed"
        if c["errors"]:
            text += f", {c['errors']} with errors"
        return text + ("" if red else " — all green")

    def to_dict(self) -> dict[str, Any]:
        return {
            "ruleset": self.ruleset,
            "version": self.version,
            "ok": self.ok,
            "summary": self.summary(),
            **self.counts,
            "files": self.files,
            "results": [r.to_dict() for r in self.results],
            "coverage": {"rules": len(self.rules), "fired": self.fired_rules, "not_fired": self.uncovered},
        }

    def junit_xml(self) -> str:
        """JUnit XML (one testsuite per scenario file), as CI servers read it."""
        return junit_xml(self.to_dict())


def junit_xml(report: dict[str, Any]) -> str:
    """JUnit XML of a report's JSON form (:meth:`TestReport.to_dict`, also what REST answers), so a
    run on a server can be written out the same way as a local one."""
    results = report.get("results", [])
    total = sum(r.get("duration_ms", 0) for r in results) / 1000
    suites = ET.Element("testsuites", name=f"rules {report.get('ruleset')}", tests=str(len(results)),
                        failures=str(report.get("failed", 0)), errors=str(report.get("errors", 0)), time=f"{total:.3f}")
    by_file: dict[str, list[dict[str, Any]]] = {}
    for result in results:
        by_file.setdefault(result["file"], []).append(result)
    for file_name in report.get("files") or sorted(by_file):
        cases = by_file.get(file_name, [])
        counts = Counter(r["status"] for r in cases)
        suite = ET.SubElement(suites, "testsuite", name=f"{report.get('ruleset')}/{file_name}", tests=str(len(cases)),
                              failures=str(counts["failed"]), errors=str(counts["error"]),
                              time=f"{sum(r.get('duration_ms', 0) for r in cases) / 1000:.3f}")
        classname = f"{report.get('ruleset')}." + file_name.rsplit(".", 1)[0].replace("/", ".")
        for result in cases:
            case = ET.SubElement(suite, "testcase", name=result["name"], classname=classname, file=file_name,
                                 line=str(result["line"]), time=f"{result.get('duration_ms', 0) / 1000:.3f}")
            if result["status"] != "passed":
                tag = "failure" if result["status"] == "failed" else "error"
                failures = result.get("failures") or []
                first = failures[0]["message"] if failures else result["status"]
                detail = "\n".join(f"{file_name}:{f['line']}: {f['message']}" for f in failures)
                detail += "\n\nactual:\n" + yaml.safe_dump(result.get("actual"), sort_keys=False, allow_unicode=True)
                ET.SubElement(case, tag, message=first, type=tag).text = detail
    coverage = report.get("coverage") or {}
    props = ET.SubElement(suites, "properties")
    ET.SubElement(props, "property", name="rules", value=str(coverage.get("rules", 0)))
    ET.SubElement(props, "property", name="rules.not_fired", value=", ".join(coverage.get("not_fired", [])))
    ET.indent(suites)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(suites, encoding="unicode") + "\n"


def text_report(report: dict[str, Any], folder: str | None = None) -> list[str]:
    """A report as terminal lines: one per scenario (✓/✗), each failure as ``path:line: message``
    (so editors can jump there), expected against actual, then coverage and the summary."""
    lines: list[str] = []
    prefix = f"{folder.rstrip('/')}/" if folder else ""
    for result in report.get("results", []):
        if result["status"] == "passed":
            lines.append(f"  ✓ {result['name']}")
            continue
        lines.append(f"  ✗ {result['name']}  ({prefix}{result['file']}:{result['line']})")
        for failure in result.get("failures", []):
            lines.append(f"      {prefix}{result['file']}:{failure['line']}: {failure['message']}")
        actual = result.get("actual") or {}
        if "fired" in actual:
            lines.append(f"      actual: fired {', '.join(actual['fired']) or 'nothing'}")
            for action in actual.get("actions", []):
                lines.append(f"              {describe_action(action)}")
    coverage = report.get("coverage") or {}
    not_fired = coverage.get("not_fired") or []
    if not_fired:
        lines.append(f"Rules no scenario fires ({len(not_fired)} of {coverage.get('rules')}): {', '.join(not_fired)}")
    elif coverage.get("rules"):
        lines.append(f"Every rule ({coverage['rules']}) is fired by a scenario.")
    version = report.get("version")
    where = f"{report.get('ruleset')}" + (f" version {version}" if version else "")
    lines.append(f"{where}: {report.get('summary')}")
    return lines


# --------------------------------------------------------------------------- parsing


class _Problems:
    def __init__(self, file: str):
        self.file = file
        self.errors: list[CompileError] = []

    def add(self, where: tuple[int, int], message: str) -> None:
        self.errors.append(CompileError(self.file, where[0], where[1], message))


def _did_you_mean(word: str, options: tuple[str, ...] | list[str]) -> str:
    close = difflib.get_close_matches(str(word), list(options), n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _unknown_keys(mapping: _Mapping, allowed: tuple[str, ...], what: str, problems: _Problems) -> None:
    for key in mapping:
        if key not in allowed:
            problems.add(mapping.key_positions[key], f"unknown key {key!r} in {what}{_did_you_mean(key, allowed)}; "
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


# --------------------------------------------------------------------------- running


def run_scenarios(engine: _Engine, files: dict[str, str], ruleset: str = "draft", version: int | None = None,
                  fire_limit: int | None = None, *, role: str | None = None) -> TestReport:
    """Runs every scenario of ``files`` on those files, compiled once (through the compile cache,
    so a deployed version's own build is reused). Raises CompileFailed when the rules do not
    compile or a scenario file is malformed: then no scenario can say anything; PolicyRefused,
    before anything compiles, when ``role`` (an author) may not run these rules."""
    from gateway.engine import compiler

    engine.check_policy(ruleset, files, role)
    scenarios, errors = parse_files(files)
    if errors:
        raise CompileFailed(errors)
    compiled = compiler.compile_cached(files, ruleset)
    results = [run_one(engine, files, scenario, compiled.rule_names, fire_limit) for scenario in scenarios]
    test_files = sorted(f for f in files if is_test_file(f))
    return TestReport(ruleset, version, results, list(compiled.rule_names), test_files)


def run_one(engine: _Engine, files: dict[str, str], scenario: Scenario, rule_names: list[str],
            fire_limit: int | None = None) -> ScenarioResult:
    started = time.perf_counter()
    try:
        result = engine.fire_files(files, scenario.given, fire_limit)
    except FactError as exc:
        failures = []
        for err in exc.errors or [{}]:
            index = err.get("index", -1)
            line = scenario.given_lines[index] if 0 <= index < len(scenario.given_lines) else scenario.line
            failures.append(Failure(f"the facts were refused: fact {index + 1 if index >= 0 else ''}"
                                    f"{' (' + err['type'] + ')' if err.get('type') else ''}: {err.get('message', exc)}",
                                    line))
        return ScenarioResult(scenario, "error", failures, {"error": str(exc)}, _ms(started))
    except CompileFailed:
        raise
    except EngineError as exc:  # a rule loop, a then-part that threw
        return ScenarioResult(scenario, "error", [Failure(f"firing failed: {exc}", scenario.line)],
                              {"error": str(exc)}, _ms(started))
    fired = [f["rule"] for f in result.fired]
    actions = [{"module": a.get("module"), "params": a.get("params", {}), "rule": a.get("rule")} for a in result.actions]
    actual = {"fired": fired, "actions": actions, "facts": result.facts}
    failures = compare(scenario, fired, actions, result.facts, rule_names)
    return ScenarioResult(scenario, "failed" if failures else "passed", failures, actual, _ms(started))


def _ms(started: float) -> float:
    return (time.perf_counter() - started) * 1000


def compare(scenario: Scenario, fired: list[str], actions: list[dict[str, Any]], facts: list[dict[str, Any]],
            rule_names: list[str]) -> list[Failure]:
    """What differs between a scenario's expectations and what happened (empty: it passed)."""
    expect = scenario.expect
    failures: list[Failure] = []
    counts = Counter(fired)
    fired_text = ", ".join(dict.fromkeys(fired)) or "none"
    for name, count in expect.fired.items():
        line = expect.lines.get(f"fired:{name}", scenario.line)
        if name not in rule_names:
            failures.append(Failure(f"there is no rule named {name!r}{_did_you_mean(name, rule_names)}", line))
        elif count is None and counts[name] == 0:
            failures.append(Failure(f"rule {name!r} did not fire (fired: {fired_text})", line))
        elif count is not None and counts[name] != count:
            failures.append(Failure(f"rule {name!r} fired {counts[name]} times, expected {count}", line))
    for name in expect.not_fired:
        line = expect.lines.get(f"not_fired:{name}", scenario.line)
        if name not in rule_names:
            failures.append(Failure(f"there is no rule named {name!r}{_did_you_mean(name, rule_names)}", line))
        elif counts[name]:
            failures.append(Failure(f"rule {name!r} fired, but must not", line))
    matched = _match_actions(expect.actions, actions, expect.ordered)
    used = set(matched.values())
    for i, wanted in enumerate(expect.actions):
        if i in matched:
            continue
        closest = _closest_action(wanted, [a for k, a in enumerate(actions) if k not in used])
        message = f"expected action {describe_action(wanted.to_dict())} was not requested"
        if expect.ordered and any(_action_matches(wanted, a) for k, a in enumerate(actions) if k not in used):
            message = f"expected action {describe_action(wanted.to_dict())} came out of order"
        elif closest is not None:
            message += f"; closest: {describe_action(closest)}"
            if closest.get("rule"):
                message += f" (from rule {closest['rule']!r})"
        elif not actions:
            message += "; no action was requested at all"
        failures.append(Failure(message, wanted.line))
    if expect.no_other_actions:
        extra = [a for k, a in enumerate(actions) if k not in used]
        if extra:
            listed = "; ".join(describe_action(a) for a in extra[:5]) + (" …" if len(extra) > 5 else "")
            failures.append(Failure(f"{len(extra)} action(s) beyond those expected: {listed}",
                                    scenario.line if not expect.actions else expect.actions[-1].line))
    taken: set[int] = set()
    for wanted, line in expect.facts:
        index = next((k for k, fact in enumerate(facts) if k not in taken and _subset(wanted, fact)), None)
        if index is None:
            same_type = sorted(_brief(f) for f in facts if f.get("type") == wanted.get("type"))
            seen = "; ".join(same_type[:3]) + (" …" if len(same_type) > 3 else "") or f"no {wanted.get('type')} fact at all"
            failures.append(Failure(f"no fact matches {_brief(wanted)} ({wanted.get('type')} facts: {seen})", line))
        else:
            taken.add(index)
    return failures


def _subset(wanted: dict[str, Any], actual: dict[str, Any]) -> bool:
    return all(key in actual and _equal(value, actual[key]) for key, value in wanted.items())


def _equal(a: Any, b: Any) -> bool:
    if isinstance(a, dict) and isinstance(b, dict):
        return _subset(a, b)
    if isinstance(a, bool) or isinstance(b, bool):
        return a is b
    return a == b


def _action_matches(wanted: ExpectedAction, actual: dict[str, Any]) -> bool:
    return wanted.module == actual.get("module") and _subset(wanted.params, actual.get("params") or {})


def _match_actions(wanted: list[ExpectedAction], actual: list[dict[str, Any]], ordered: bool) -> dict[int, int]:
    """expected index -> actual index: each expected action takes a distinct actual one. In order,
    a subsequence; otherwise a maximum bipartite matching (so a loose expectation listed first
    cannot take the action a stricter one needs)."""
    if ordered:
        out, start = {}, 0
        for i, w in enumerate(wanted):
            k = next((k for k in range(start, len(actual)) if _action_matches(w, actual[k])), None)
            if k is not None:
                out[i], start = k, k + 1
        return out
    candidates = [[k for k, a in enumerate(actual) if _action_matches(w, a)] for w in wanted]
    owner: dict[int, int] = {}

    def assign(i: int, seen: set[int]) -> bool:
        for k in candidates[i]:
            if k in seen:
                continue
            seen.add(k)
            if k not in owner or assign(owner[k], seen):
                owner[k] = i
                return True
        return False

    for i in range(len(wanted)):
        assign(i, set())
    return {i: k for k, i in owner.items()}


def _closest_action(wanted: ExpectedAction, actual: list[dict[str, Any]]) -> dict[str, Any] | None:
    same = [a for a in actual if a.get("module") == wanted.module]
    if not same:
        return None
    return max(same, key=lambda a: sum(_equal(v, (a.get("params") or {}).get(k)) for k, v in wanted.params.items()))


def describe_action(action: dict[str, Any]) -> str:
    """``say {robot: pepper, text: "Welcome"}``: an action as one readable line."""
    params = action.get("params") or {}
    inner = ", ".join(f"{k}: {_value_text(v)}" for k, v in params.items())
    return f"{action.get('module')} {{{inner}}}"


def _value_text(value: Any) -> str:
    if isinstance(value, str):  # quoted unless one plain word: {robot: pepper, text: "Welcome. Two seats?"}
        return value if re.fullmatch(r"[\w-]+", value) else '"' + value.replace('"', '\\"') + '"'
    return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("...").strip()


def _brief(fact: dict[str, Any]) -> str:
    fields = ", ".join(f"{k}: {_value_text(v)}" for k, v in fact.items() if k != "type" and v is not None)
    return f"{fact.get('type')} {{{fields}}}"


def require_green(engine: _Engine, name: str, files: dict[str, str]) -> TestReport | None:
    """The deploy gate: runs the scenarios of ``files`` (if it has any) and refuses a red rule set
    with :class:`ScenariosFailed` listing each failure at its file and line. Compile errors raise
    CompileFailed as the deploy itself would."""
    from gateway.engine.errors import ScenariosFailed
    from gateway.engine.ruleset import check_files, is_test_file

    if not any(is_test_file(f) for f in files):
        return None
    check_files(files)
    report = run_scenarios(engine, files, name)
    if report.ok:
        return report
    red = report.red()
    first = red[0]
    detail = first.failures[0].message if first.failures else first.status
    raise ScenariosFailed(
        f"not deployed: {len(red)} of {len(report.results)} scenarios are red "
        f"(first: '{first.scenario.name}': {detail}); fix the rules or the scenarios, or deploy with \"force\": true",
        [p.to_dict() for p in report.problems()], report.to_dict())
