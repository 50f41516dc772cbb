"""Reading workflow YAML: syntax, then the JSON schema, then references — every error with a place.

Why three passes: YAML errors come with a line and column from the parser; schema errors come with
a path inside the document, which we map back to the line and column of that node; reference errors
(a step naming a module that does not exist, a process calling itself, a bad expression) need the
whole document. All problems are collected and reported together, nothing is half-loaded.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from functools import lru_cache
from importlib import resources
from pathlib import Path
from typing import Any, Iterable

import jsonschema
import yaml

from gateway.workflow import expr
from gateway.workflow.model import (
    Actor, BranchStep, Module, ModuleStep, Process, ProcessStep, Route, Service, SetStep, Step, Workflow,
)

PathT = tuple[Any, ...]
_MODULE_BASE_KEYS = {"kind", "description", "actor", "timeout", "params"}


@dataclass(frozen=True)
class Problem:
    """One error: which file, where in the document (path, line, column; 1-based), and what."""

    file: str
    path: str
    line: int
    column: int
    message: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def __str__(self) -> str:
        where = f"{self.file}:{self.line}:{self.column}" if self.line else self.file
        return f"{where}: {self.path or '(document)'}: {self.message}"


class WorkflowInvalid(ValueError):
    """The workflow text is not valid; ``problems`` lists every error found."""

    def __init__(self, problems: list[Problem]) -> None:
        self.problems = problems
        super().__init__("\n".join(str(p) for p in problems))

    def to_dict(self) -> dict[str, Any]:
        return {"error": "workflow_invalid", "problems": [p.to_dict() for p in self.problems]}


@lru_cache(maxsize=1)
def schema() -> dict[str, Any]:
    """The workflow JSON schema (shipped as ``gateway/workflow/schema.json``)."""
    text = resources.files("gateway.workflow").joinpath("schema.json").read_text(encoding="utf-8")
    return json.loads(text)


def format_path(path: Iterable[Any]) -> str:
    """``("processes", "greet", "steps", 1)`` -> ``processes.greet.steps[1]``."""
    out = ""
    for part in path:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
    return out


class _Places:
    """Line/column of every node of a YAML document, by path."""

    def __init__(self, root: yaml.Node | None) -> None:
        self._marks: dict[PathT, tuple[int, int]] = {}
        self.duplicates: list[tuple[PathT, tuple[int, int]]] = []  # a repeated key would lose data
        if root is not None:
            self._walk(root, ())

    def _walk(self, node: yaml.Node, path: PathT) -> None:
        self._marks[path] = (node.start_mark.line + 1, node.start_mark.column + 1)
        if isinstance(node, yaml.MappingNode):
            seen: set[Any] = set()
            for key, value in node.value:
                if key.value in seen:
                    self.duplicates.append((path + (key.value,), (key.start_mark.line + 1, key.start_mark.column + 1)))
                seen.add(key.value)
                child = path + (key.value,)
                self._walk(value, child)
                # a problem about a key itself ("unknown property") points at the key
                self._marks[child + ("<key>",)] = (key.start_mark.line + 1, key.start_mark.column + 1)
        elif isinstance(node, yaml.SequenceNode):
            for index, item in enumerate(node.value):
                self._walk(item, path + (index,))

    def of(self, path: PathT, key: str | None = None) -> tuple[int, int]:
        """The place of ``path`` (or of ``key`` under it), else of its nearest known parent."""
        if key is not None and path + (key, "<key>") in self._marks:
            return self._marks[path + (key, "<key>")]
        for cut in range(len(path), -1, -1):
            if path[:cut] in self._marks:
                return self._marks[path[:cut]]
        return (0, 0)


class _Collector:
    def __init__(self, file: str, places: _Places) -> None:
        self.file = file
        self.places = places
        self.problems: list[Problem] = []

    def add(self, path: PathT, message: str, key: str | None = None) -> None:
        line, column = self.places.of(path, key)
        shown = path + (key,) if key is not None else path
        self.problems.append(Problem(self.file, format_path(shown), line, column, message))


#: libyaml's loader when PyYAML has it (about ten times faster: every gateway start parses the seeded
#: workflows), else the pure-Python one; both give the same nodes, marks and data.
_Loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def _construct(root: yaml.Node | None) -> Any:
    """The data of a composed document (what ``safe_load`` gives), without parsing the text again."""
    if root is None:
        return None
    loader = _Loader("")
    try:
        return loader.construct_document(root)
    finally:
        loader.dispose()


#: Deepest nesting a workflow may have (real ones need under 15): checked on the parser's events,
#: before anything builds the document recursively.
MAX_DEPTH = 100


def _check_events(text: str, file: str) -> None:
    """Refuses aliases, which can blow a small text up exponentially (and no workflow needs them), and
    documents nested deeper than :data:`MAX_DEPTH`, in one pass over the parser's events."""
    depth = 0
    for event in yaml.parse(text, Loader=_Loader):
        if isinstance(event, yaml.AliasEvent):
            mark = event.start_mark
            raise WorkflowInvalid([Problem(file, "", mark.line + 1, mark.column + 1,
                                           "YAML aliases (*name) are not allowed in workflows")])
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > MAX_DEPTH:
                mark = event.start_mark
                raise WorkflowInvalid([Problem(file, "", mark.line + 1, mark.column + 1,
                                               "the document is nested too deeply")])
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1


def parse(text: str, file: str = "<workflow>") -> Workflow:
    """Parse and validate workflow YAML text; raises :class:`WorkflowInvalid` with all problems."""
    try:
        _check_events(text, file)
        root = yaml.compose(text, Loader=_Loader)
        data = _construct(root)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line, column = (mark.line + 1, mark.column + 1) if mark else (0, 0)
        message = f"YAML syntax error: {exc.problem or exc}" + (f" ({exc.context})" if exc.context else "")
        raise WorkflowInvalid([Problem(file, "", line, column, message)]) from None
    except yaml.YAMLError as exc:
        raise WorkflowInvalid([Problem(file, "", 0, 0, f"YAML error: {exc}")]) from None
    except RecursionError:
        raise WorkflowInvalid([Problem(file, "", 0, 0, "the document is nested too deeply")]) from None
    try:
        places = _Places(root)
    except RecursionError:
        raise WorkflowInvalid([Problem(file, "", 0, 0, "the document is nested too deeply")]) from None
    errors = _Collector(file, places)
    for path, (line, column) in places.duplicates:
        errors.problems.append(Problem(file, format_path(path), line, column,
                                       f"duplicate key {path[-1]!r} (the earlier value would be lost)"))
    if not isinstance(data, dict):
        errors.add((), f"a workflow must be a mapping, got {type(data).__name__}")
        raise WorkflowInvalid(errors.problems)
    try:
        _check_schema(data, errors)
    except RecursionError:
        errors.add((), "the document is nested too deeply")
    if errors.problems:
        raise WorkflowInvalid(errors.problems)
    workflow = _build(data, text)
    _check_references(workflow, data, errors)
    if errors.problems:
        raise WorkflowInvalid(errors.problems)
    return workflow


def load(path: str | Path) -> Workflow:
    """Read and parse one workflow file."""
    path = Path(path)
    return parse(path.read_text(encoding="utf-8"), file=str(path))


def _check_schema(data: dict[str, Any], errors: _Collector) -> None:
    validator = jsonschema.Draft202012Validator(schema())
    for error in sorted(validator.iter_errors(data), key=lambda e: list(map(str, e.absolute_path))):
        for leaf in _leaves(error):
            path = tuple(leaf.absolute_path)
            key = None
            if leaf.validator == "additionalProperties" and isinstance(leaf.instance, dict):
                extra = _unexpected_keys(leaf)
                for name in extra:
                    errors.add(path, f"unknown field {name!r}", key=name)
                if extra:
                    continue
            errors.add(path, _message(leaf), key=key)


def _leaves(error: jsonschema.ValidationError) -> list[jsonschema.ValidationError]:
    """For if/then and oneOf failures, report the specific inner errors (they say more)."""
    if error.validator == "oneOf" and isinstance(error.instance, dict) and error.absolute_path \
            and isinstance(error.absolute_path[-1], int):
        return [error]
    if error.context:
        best = jsonschema.exceptions.best_match(error.context)
        return [best] if best is not None else [error]
    return [error]


def _unexpected_keys(error: jsonschema.ValidationError) -> list[str]:
    schema_ = error.schema
    allowed = set(schema_.get("properties", {}))
    patterns = list(schema_.get("patternProperties", {}))
    import re

    return [k for k in error.instance if k not in allowed and not any(re.search(p, k) for p in patterns)]


def _message(error: jsonschema.ValidationError) -> str:
    if error.validator == "oneOf" and isinstance(error.instance, dict):
        kinds = [k for k in ("module", "process", "if", "set") if k in error.instance]
        if not kinds:
            return "a step needs one of: module, process, if, set"
        return f"a step must be exactly one of module/process/if/set, got {', '.join(kinds)}"
    if error.validator == "pattern":
        return f"{error.instance!r} is not a valid name here (expected pattern {error.validator_value})"
    if error.validator == "enum":
        return f"{error.instance!r} is not one of {', '.join(map(str, error.validator_value))}"
    if error.validator == "required":
        return error.message.replace("is a required property", "is required")
    return error.message


# ---------------------------------------------------------------- building the model


def _build(data: dict[str, Any], text: str) -> Workflow:
    modules = {name: _module(name, spec) for name, spec in data["modules"].items()}
    processes = {
        name: Process(name, _steps(spec["steps"], name), spec.get("description", ""))
        for name, spec in data["processes"].items()
    }
    services = {
        name: Service(name, tuple(spec["processes"]), spec.get("description", ""))
        for name, spec in data["services"].items()
    }
    route_spec = data["route"]
    route = Route(tuple(route_spec["services"]), route_spec.get("start", "start"), route_spec.get("end", "end"))
    actors = {
        name: Actor(name, spec.get("kind", "system"), spec.get("label", name))
        for name, spec in (data.get("actors") or {}).items()
    }
    return Workflow(
        name=data["workflow"], modules=modules, processes=processes, services=services, route=route,
        actors=actors, inputs=dict(data.get("inputs") or {}), title=data.get("title", ""),
        description=data.get("description", ""), business_process=data.get("business_process"), source=text,
    )


def _module(name: str, spec: dict[str, Any]) -> Module:
    options = {k: v for k, v in spec.items() if k not in _MODULE_BASE_KEYS}
    return Module(name=name, kind=spec["kind"], actor=spec.get("actor"), timeout=spec.get("timeout"),
                  params=dict(spec.get("params") or {}), options=options, description=spec.get("description", ""))


def _steps(specs: list[dict[str, Any]], prefix: str) -> tuple[Step, ...]:
    return tuple(_step(spec, f"{prefix}_{i + 1}") for i, spec in enumerate(specs))


def _step(spec: dict[str, Any], default_id: str) -> Step:
    step_id = spec.get("id", default_id)
    label = spec.get("label", "")
    if "module" in spec:
        return ModuleStep(id=step_id, module=spec["module"], params=dict(spec.get("with") or {}),
                          save=spec.get("save"), actor=spec.get("actor"), timeout=spec.get("timeout"),
                          on_failure=spec.get("on_failure", "fail"), retries=spec.get("retries", 0), label=label)
    if "process" in spec:
        return ProcessStep(id=step_id, process=spec["process"], params=dict(spec.get("with") or {}),
                           save=spec.get("save"), on_failure=spec.get("on_failure", "fail"), label=label)
    if "if" in spec:
        return BranchStep(id=step_id, condition=spec["if"], then=_steps(spec["then"], f"{step_id}_then"),
                          otherwise=_steps(spec.get("else") or [], f"{step_id}_else"), label=label)
    return SetStep(id=step_id, values=dict(spec["set"]), label=label)


# ---------------------------------------------------------------- references and expressions


def _check_references(wf: Workflow, data: dict[str, Any], errors: _Collector) -> None:
    for name, module in wf.modules.items():
        path = ("modules", name)
        if module.actor and module.actor not in wf.actors:
            errors.add(path + ("actor",), f"unknown actor {module.actor!r} (declare it under actors)")
        for action, target in (module.options.get("dispatch") or {}).items():
            if target not in wf.modules:
                errors.add(path + ("dispatch", action), f"unknown module {target!r}")
        _check_templates(module.params, path + ("params",), errors)
    seen_ids: dict[str, PathT] = {}
    for name, process in wf.processes.items():
        _check_steps(wf, process.steps, data["processes"][name]["steps"], ("processes", name, "steps"),
                     seen_ids, errors)
    for name, service in wf.services.items():
        for i, process in enumerate(service.processes):
            if process not in wf.processes:
                errors.add(("services", name, "processes", i), f"unknown process {process!r}")
    for i, service in enumerate(wf.route.services):
        if service not in wf.services:
            errors.add(("route", "services", i), f"unknown service {service!r}")
    cycle = _find_cycle(wf)
    if cycle:
        errors.add(("processes", cycle[0]), "processes call each other in a cycle: " + " -> ".join(cycle))


def _check_steps(wf: Workflow, steps: tuple[Step, ...], specs: list[Any], path: PathT,
                 seen_ids: dict[str, PathT], errors: _Collector) -> None:
    for i, (step, spec) in enumerate(zip(steps, specs)):
        here = path + (i,)
        if step.id in seen_ids:
            errors.add(here, f"step id {step.id!r} is used twice (first at {format_path(seen_ids[step.id])})")
        seen_ids.setdefault(step.id, here)
        if isinstance(step, ModuleStep):
            if step.module not in wf.modules:
                errors.add(here + ("module",), f"unknown module {step.module!r}")
            elif wf.modules[step.module].kind == "wait":
                _check_wait(step.module, {**wf.modules[step.module].params, **step.params}, step.params, here, errors)
            if step.actor and step.actor not in wf.actors:
                errors.add(here + ("actor",), f"unknown actor {step.actor!r} (declare it under actors)")
            if step.on_failure != "retry" and step.retries:
                errors.add(here + ("retries",), "retries only apply with on_failure: retry")
        elif isinstance(step, ProcessStep):
            if step.process not in wf.processes:
                errors.add(here + ("process",), f"unknown process {step.process!r}")
        elif isinstance(step, BranchStep):
            _check_expression(step.condition, here + ("if",), errors)
            _check_steps(wf, step.then, spec["then"], here + ("then",), seen_ids, errors)
            _check_steps(wf, step.otherwise, spec.get("else") or [], here + ("else",), seen_ids, errors)
        params = step.values if isinstance(step, SetStep) else getattr(step, "params", {})
        _check_templates(params, here + ("set" if isinstance(step, SetStep) else "with",), errors)


def _check_wait(module: str, merged: dict[str, Any], own: dict[str, Any], path: PathT, errors: _Collector) -> None:
    """A wait needs a number of seconds (or a ``${...}`` template giving one): the step's ``with``
    field when it sets one, else the module's default."""
    if "seconds" not in merged:
        errors.add(path, f"wait module {module!r} needs a 'seconds' parameter")
        return
    seconds = merged["seconds"]
    if isinstance(seconds, str) and "${" in seconds:
        return
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not 0 <= seconds <= 3600:
        where = path + ("with", "seconds") if "seconds" in own else ("modules", module, "params", "seconds")
        errors.add(where, f"{seconds!r} is not a number of seconds (0 to 3600)")


def _check_templates(value: Any, path: PathT, errors: _Collector) -> None:
    try:
        expressions = expr.template_expressions(value)
    except expr.ExpressionError as exc:
        errors.add(path, str(exc))
        return
    for expression in expressions:
        _check_expression(expression, path, errors)


def _check_expression(expression: str, path: PathT, errors: _Collector) -> None:
    problem = expr.check_syntax(expression)
    if problem:
        errors.add(path, problem)


def _find_cycle(wf: Workflow) -> list[str] | None:
    """A process that (indirectly) runs itself would never end: find one such chain."""
    calls = {name: _called_processes(p.steps) for name, p in wf.processes.items()}
    state: dict[str, int] = {}

    def visit(name: str, chain: list[str]) -> list[str] | None:
        state[name] = 1
        for callee in calls.get(name, ()):
            if state.get(callee) == 1:
                return chain + [name, callee]
            if callee in calls and not state.get(callee):
                found = visit(callee, chain + [name])
                if found:
                    return found
        state[name] = 2
        return None

    for name in calls:
        if not state.get(name):
            found = visit(name, [])
            if found:
                return found[found.index(found[-1]):]
    return None


def _called_processes(steps: tuple[Step, ...]) -> list[str]:
    called: list[str] = []
    for step in steps:
        if isinstance(step, ProcessStep):
            called.append(step.process)
        elif isinstance(step, BranchStep):
            called.extend(_called_processes(step.then) + _called_processes(step.otherwise))
    return called


def iter_steps(steps: tuple[Step, ...]) -> Iterable[Step]:
    """Every step, depth first, including those inside branches."""
    for step in steps:
        yield step
        if isinstance(step, BranchStep):
            yield from iter_steps(step.then)
            yield from iter_steps(step.otherwise)
