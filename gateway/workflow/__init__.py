"""Workflows in the papers' terms (modules, processes, services, a route), run live by the gateway.

    from gateway.workflow import parse, load, Executor, WorkflowRegistry, build_service, generate

See docs/workflows.md. The core (loader, executor, registry) is plain Python; ROS, the rules engine,
the ontology and humans are pluggable adapters.
"""

from gateway.workflow.codegen import generate
from gateway.workflow.executor import Executor, RunResult, StepRecord
from gateway.workflow.loader import Problem, WorkflowInvalid, load, parse
from gateway.workflow.model import Workflow
from gateway.workflow.registry import WorkflowConflict, WorkflowNotFound, WorkflowRegistry
from gateway.workflow.service import WorkflowService, build_service

__all__ = [
    "Executor", "Problem", "RunResult", "StepRecord", "Workflow", "WorkflowConflict", "WorkflowInvalid",
    "WorkflowNotFound", "WorkflowRegistry", "WorkflowService", "build_service", "generate", "load", "parse",
]
