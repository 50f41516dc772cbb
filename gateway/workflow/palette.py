"""The palette of the visual workflow editor: the modules an owner can put into a workflow, built
from what really exists, each with typed parameters the editor turns into a form.

Why built here and not written down: a palette that lists a robot that is not configured, a rule
set that is not deployed or an ontology value that is not there would let the owner build a
workflow that fails at run time. So the entries come from

- the ROS service interfaces (``ros/printeps_interfaces/srv/*.srv``: their request fields are the
  step's parameters) and the robots: the configured ones (``ros.robots``, every robot service under
  their namespace) and those the stored workflows already drive (the services they use);
- the deployed rule sets (``fire_rules``), the ontology's ``individual.property`` values
  (``ontology_value``), and the kinds with no outside world (``wait``, ``manual``, branches).

A parameter is ``{name, type, required, default, choices, description}``; types are ``string``,
``number`` (a number or a ``${...}`` template), ``integer``, ``expression``, ``robot``,
``ruleset``, ``ontology_value``, ``module`` (a module of the same workflow) and ``dispatch``
(rule action -> module).
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from gateway.workflow.model import Workflow

#: ROS field type -> palette parameter type.
_FIELD_TYPES = {"string": "string", "float32": "number", "float64": "number", "int32": "integer",
                "int64": "integer", "uint32": "integer", "bool": "boolean"}

#: What a robot service does, in the owner's words (by service name); others get their srv name.
_SERVICE_LABELS = {"speak": "say", "gesture": "gesture / motion", "move_to": "move to"}

#: Module names the editor suggests for a new module of a service (the teahouse workflows' names).
_SERVICE_MODULES = {"speak": "say", "gesture": "gesture", "move_to": "move_to"}

_FIELD_HELP = {
    "text": "What the robot says.",
    "name": "The gesture or motion to perform.",
    "location": "A named place (e.g. table1, entrance); x/y are used when it is empty.",
    "x": "Where to go: x in metres (a number or ${...}).",
    "y": "Where to go: y in metres (a number or ${...}).",
}


@dataclass(frozen=True)
class Param:
    """One typed parameter of a module or step: what the editor's form field is built from."""

    name: str
    type: str
    required: bool = False
    default: Any = None
    choices: list[Any] | None = None
    description: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {k: v for k, v in asdict(self).items() if v is not None}


@dataclass(frozen=True)
class Interface:
    """A ROS service type and its request fields."""

    type: str  # printeps_interfaces/srv/Speak
    request: list[tuple[str, str]]  # (field, ROS type)
    comments: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"type": self.type, "request": [{"name": n, "type": t, "description": self.comments.get(n, "")}
                                               for n, t in self.request]}


@dataclass(frozen=True)
class Robot:
    """A robot the editor can command: its name, service namespace, and services (name -> srv type)."""

    name: str
    namespace: str
    services: dict[str, str]
    configured: bool

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def read_interfaces(folder: str | Path) -> dict[str, Interface]:
    """``<package>/srv/*.srv`` under ``folder`` -> interfaces by type (``pkg/srv/Name``)."""
    out: dict[str, Interface] = {}
    for path in sorted(Path(folder).glob("*/srv/*.srv")):
        request, comments, pending = [], {}, ""
        for line in path.read_text(encoding="utf-8").splitlines():
            stripped = line.strip()
            if stripped == "---":
                break
            if stripped.startswith("#"):
                pending = stripped.lstrip("# ").strip()
                continue
            parts = stripped.split()
            if len(parts) >= 2:
                request.append((parts[1], parts[0]))
                if pending:
                    comments[parts[1]] = pending
            pending = ""
        kind = f"{path.parent.parent.name}/srv/{path.stem}"
        out[kind] = Interface(kind, request, comments)
    return out


def _service_name(srv_type: str) -> str:
    """``printeps_interfaces/srv/MoveTo`` -> ``move_to``."""
    stem = srv_type.rsplit("/", 1)[-1]
    return re.sub(r"(?<!^)(?=[A-Z])", "_", stem).lower()


def robots_of(configured: Mapping[str, str], interfaces: Mapping[str, Interface],
              workflows: Iterable[Workflow]) -> list[Robot]:
    """Configured robots offer every robot service under their namespace; robots the workflows
    drive (actors of kind robot) offer the services those workflows call."""
    robot_srvs = {_service_name(t): t for t in interfaces if not t.endswith("/FireBusinessRules")}
    robots: dict[str, Robot] = {
        name: Robot(name, "/" + ns.strip("/"), {svc: t for svc, t in sorted(robot_srvs.items())}, True)
        for name, ns in configured.items()
    }
    for wf in workflows:
        for module in wf.modules.values():
            actor = wf.actors.get(module.actor or "")
            service = module.options.get("service")
            if module.kind != "ros_service" or actor is None or actor.kind != "robot" or not service:
                continue
            robot = str(module.params.get("robot") or actor.name)
            namespace, _, svc = str(service).rpartition("/")
            known = robots.get(robot) or Robot(robot, namespace or f"/{robot}", {}, False)
            services = {**known.services, svc: str(module.options.get("type"))}
            robots[robot] = Robot(robot, known.namespace, dict(sorted(services.items())), known.configured)
    return [robots[name] for name in sorted(robots)]


def _robot_entries(robots: list[Robot], interfaces: Mapping[str, Interface]) -> list[dict[str, Any]]:
    entries = []
    for robot in robots:
        for svc, srv_type in robot.services.items():
            interface = interfaces.get(srv_type)
            fields = interface.request if interface else []
            params = [Param("robot", "robot", True, robot.name, [r.name for r in robots],
                            "The robot that does it.")]
            for name, ros_type in fields:
                if name == "robot":
                    continue
                required = name in ("text", "name")
                help_text = (interface.comments.get(name) if interface else "") or _FIELD_HELP.get(name, "")
                params.append(Param(name, _FIELD_TYPES.get(ros_type, "string"), required, None, None, help_text))
            label = _SERVICE_LABELS.get(svc, svc.replace("_", " "))
            entries.append({
                "id": f"{robot.name}.{svc}", "group": "Robot services", "kind": "ros_service",
                "label": f"{robot.name.capitalize()}: {label}",
                "description": f"Calls {robot.namespace}/{svc} ({srv_type}).",
                "module_name": _SERVICE_MODULES.get(svc, svc) if robot.configured else f"{robot.name}_{svc}",
                "module": {"kind": "ros_service", "actor": robot.name, "service": f"{robot.namespace}/{svc}",
                           "type": srv_type, "params": {"robot": robot.name}},
                "actor": {"name": robot.name, "kind": "robot", "label": robot.name.capitalize()},
                "params": [p.to_dict() for p in params],
            })
    return entries


def build_palette(*, configured_robots: Mapping[str, str], interfaces: Mapping[str, Interface],
                  workflows: Iterable[Workflow], rulesets: list[str],
                  ontology_values: Mapping[str, Any]) -> dict[str, Any]:
    """The palette: ``robots``, ``rulesets``, ``ontology_values``, ``interfaces`` and ``entries``
    (each: id, group, kind, label, description, module_name, module, params, module_params)."""
    workflows = list(workflows)
    robots = robots_of(configured_robots, interfaces, workflows)
    values = [{"name": k, "value": v} for k, v in sorted(ontology_values.items())]
    entries = _robot_entries(robots, interfaces)
    entries.append({
        "id": "fire_rules", "group": "Business rules", "kind": "fire_rules", "label": "Fire business rules",
        "description": "Fire a deployed rule set with facts; its then-part actions run through this "
                       "workflow's modules.",
        "module_name": "fire_rules",
        "module": {"kind": "fire_rules", "actor": "gateway", "ruleset": rulesets[0] if rulesets else "",
                   "dispatch": {}},
        "actor": {"name": "gateway", "kind": "system", "label": "Rules engine"},
        "module_params": [
            Param("ruleset", "ruleset", True, rulesets[0] if rulesets else None, list(rulesets),
                  "The deployed rule set to fire.").to_dict(),
            Param("dispatch", "dispatch", False, {}, None,
                  "Which module of this workflow performs each then-part action (say -> say).").to_dict(),
        ],
        "params": [Param("facts", "expression", True, "${[]}", None,
                         "The facts to fire with: a ${...} expression giving a list of fact objects.").to_dict()],
    })
    entries.append({
        "id": "ontology_value", "group": "Knowledge", "kind": "ontology_value", "label": "Look up an ontology value",
        "description": "Read one value of the teahouse ontology (asserted or inferred) for the next steps.",
        "module_name": "ontology",
        "module": {"kind": "ontology_value", "actor": "knowledge"},
        "actor": {"name": "knowledge", "kind": "system", "label": "Teahouse ontology"},
        "params": [Param("name", "ontology_value", True, values[0]["name"] if values else None,
                         [v["name"] for v in values], "individual.property of the ontology.").to_dict(),
                   Param("default", "string", False, None, None,
                         "Used when the ontology has no such value.").to_dict()],
        "save": True,
    })
    entries.append({
        "id": "dialogue", "group": "Dialogue", "kind": "dialogue", "label": "Take the order by talking",
        "description": "Pepper talks with the customer at a table (the dialogue rules) until the order is "
                       "complete; the next steps get the order (drink, cups).",
        "module_name": "dialogue",
        "module": {"kind": "dialogue", "actor": "pepper"},
        "actor": {"name": "pepper", "kind": "robot", "label": "Pepper"},
        "params": [Param("conversation", "string", True, "${input.table.id}", None,
                         "The conversation: one per table.").to_dict(),
                   Param("opening", "string", False, "What would you like to drink?", None,
                         "What Pepper says first.").to_dict(),
                   Param("customer_says", "expression", False, None, None,
                         "A simulated customer's sentences (empty: wait for real customers).").to_dict()],
        "save": True,
    })
    entries.append({
        "id": "wait", "group": "Timing", "kind": "wait", "label": "Wait",
        "description": "Pause the workflow for some seconds (e.g. let the customers finish).",
        "module_name": "pause",
        "module": {"kind": "wait", "params": {"seconds": 1}},
        "module_params": [Param("seconds", "number", True, 1, None, "Default pause in seconds (0 to 3600).").to_dict()],
        "params": [Param("seconds", "number", False, None, None,
                         "Seconds for this step (empty: the module's default).").to_dict()],
    })
    entries.append({
        "id": "manual", "group": "People", "kind": "manual", "label": "Task for staff",
        "description": "A step a person does (shown as a task until marked done).",
        "module_name": "staff_task",
        "module": {"kind": "manual", "actor": "staff"},
        "actor": {"name": "staff", "kind": "human", "label": "Staff"},
        "params": [Param("prompt", "string", True, None, None, "What the person should do.").to_dict(),
                   Param("sim_seconds", "number", False, None, None,
                         "How long simulated staff take (demo).").to_dict()],
    })
    entries.append({
        "id": "branch", "group": "Flow", "kind": "branch", "label": "Branch (if / then / else)",
        "description": "Run the then-arm when the condition holds, else the else-arm.",
        "params": [Param("if", "expression", True, "True", None,
                         "A condition over the inputs and saved values, e.g. len(input.orders) > 0.").to_dict()],
    })
    entries.append({
        "id": "set", "group": "Flow", "kind": "set", "label": "Set variables",
        "description": "Give names to values (texts, numbers, ${…} expressions) that later steps read as ${name}.",
        "params": [],
    })
    return {
        "robots": [r.to_dict() for r in robots],
        "rulesets": list(rulesets),
        "ontology_values": values,
        "interfaces": [i.to_dict() for i in interfaces.values()],
        "step_params": [
            Param("id", "name", True, None, None,
                  "The step's name (letters, digits, _), unique in the workflow.").to_dict(),
            Param("label", "string", False, None, None, "A caption for the views.").to_dict(),
            Param("save", "name", False, None, None, "Keep the output under this name for later steps.").to_dict(),
            Param("on_failure", "string", False, "fail", ["fail", "continue", "retry"],
                  "What a failure does: stop the run, go on, or retry.").to_dict(),
            Param("retries", "integer", False, None, None, "With on_failure retry: how often (0 to 10).").to_dict(),
            Param("timeout", "number", False, None, None, "Seconds before the step times out.").to_dict(),
        ],
        "entries": entries,
    }
