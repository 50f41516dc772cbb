"""The workflow model in the papers' terms: modules, processes, services, a route, and actors.

Why plain frozen dataclasses: a loaded workflow is an immutable snapshot. A run keeps the snapshot
it started with, so replacing a workflow while it runs is safe (the next run uses the new one).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Union

MODULE_KINDS = ("ros_service", "ros_topic", "fire_rules", "manual", "wait", "ontology_value", "dialogue")
FAILURE_POLICIES = ("fail", "continue", "retry")


@dataclass(frozen=True)
class Actor:
    """Who performs steps (for the scenario view): a robot, a human, the system, a sensor."""

    name: str
    kind: str = "system"
    label: str = ""


@dataclass(frozen=True)
class Module:
    """A primitive function. ``options`` holds the kind's own fields (service, type, ruleset, ...)."""

    name: str
    kind: str
    actor: str | None = None
    timeout: float | None = None
    params: dict[str, Any] = field(default_factory=dict)
    options: dict[str, Any] = field(default_factory=dict)
    description: str = ""


@dataclass(frozen=True)
class ModuleStep:
    """Call one module with parameters; optionally save its output under a name."""

    id: str
    module: str
    params: dict[str, Any] = field(default_factory=dict)
    save: str | None = None
    actor: str | None = None
    timeout: float | None = None
    on_failure: str = "fail"
    retries: int = 0
    label: str = ""


@dataclass(frozen=True)
class ProcessStep:
    """Run another process (processes nest); its ``with`` values become variables inside it."""

    id: str
    process: str
    params: dict[str, Any] = field(default_factory=dict)
    save: str | None = None
    on_failure: str = "fail"
    label: str = ""


@dataclass(frozen=True)
class BranchStep:
    """``if`` an expression holds run ``then`` steps, otherwise ``else`` steps."""

    id: str
    condition: str
    then: tuple["Step", ...]
    otherwise: tuple["Step", ...] = ()
    label: str = ""


@dataclass(frozen=True)
class SetStep:
    """Assign variables from expressions/templates (data passing without a module call)."""

    id: str
    values: dict[str, Any]
    label: str = ""


Step = Union[ModuleStep, ProcessStep, BranchStep, SetStep]


@dataclass(frozen=True)
class Process:
    name: str
    steps: tuple[Step, ...]
    description: str = ""


@dataclass(frozen=True)
class Service:
    """A business-level function composed only of processes."""

    name: str
    processes: tuple[str, ...]
    description: str = ""


@dataclass(frozen=True)
class Route:
    """The first hierarchy: route start, the service list, route end."""

    services: tuple[str, ...]
    start: str = "start"
    end: str = "end"


@dataclass(frozen=True)
class Workflow:
    name: str
    modules: dict[str, Module]
    processes: dict[str, Process]
    services: dict[str, Service]
    route: Route
    actors: dict[str, Actor] = field(default_factory=dict)
    inputs: dict[str, Any] = field(default_factory=dict)
    title: str = ""
    description: str = ""
    business_process: int | None = None
    source: str = ""

    def step_actor(self, step: ModuleStep) -> str | None:
        """The actor of a module step: the step's own, else its module's."""
        if step.actor:
            return step.actor
        module = self.modules.get(step.module)
        return module.actor if module else None
