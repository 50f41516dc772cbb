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
(:func:`gateway.engine.scenario_files.format_errors`, which the compiler also reports, so nothing
with a broken scenario file deploys); :func:`run_scenarios` fires each scenario through the engine on the compiled rule set
(one build for all of them) and compares; the :class:`TestReport` gives the expected and actual of
every scenario, the rules no scenario fires (coverage) and JUnit XML for CI.
"""

from __future__ import annotations

import re
import time
import xml.etree.ElementTree as ET
from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Protocol

import yaml

from gateway.engine import compiler
from gateway.engine.errors import CompileError, CompileFailed, EngineError, FactError, ScenariosFailed
from gateway.engine.ruleset import check_files, is_test_file
from gateway.engine.scenario_files import ExpectedAction, Scenario, did_you_mean, parse_files


class _Engine(Protocol):  # what the runner needs of gateway.engine.Engine
    def fire_files(self, files: dict[str, str], facts: list[dict[str, Any]], fire_limit: int | None = None) -> Any: ...

    def check_policy(self, name: str, files: dict[str, str], role: str | None) -> None: ...


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


# --------------------------------------------------------------------------- running


def run_scenarios(engine: _Engine, files: dict[str, str], ruleset: str = "draft", version: int | None = None,
                  fire_limit: int | None = None, *, role: str | None = None) -> TestReport:
    """Runs every scenario of ``files`` on those files, compiled once (through the compile cache,
    so a deployed version's own build is reused). Raises CompileFailed when the rules do not
    compile or a scenario file is malformed: then no scenario can say anything; PolicyRefused,
    before anything compiles, when ``role`` (an author) may not run these rules."""
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
            failures.append(Failure(f"there is no rule named {name!r}{did_you_mean(name, rule_names)}", line))
        elif count is None and counts[name] == 0:
            failures.append(Failure(f"rule {name!r} did not fire (fired: {fired_text})", line))
        elif count is not None and counts[name] != count:
            failures.append(Failure(f"rule {name!r} fired {counts[name]} times, expected {count}", line))
    for name in expect.not_fired:
        line = expect.lines.get(f"not_fired:{name}", scenario.line)
        if name not in rule_names:
            failures.append(Failure(f"there is no rule named {name!r}{did_you_mean(name, rule_names)}", line))
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
