"""The rules engine: Drools (executable model) embedded through JPype.

See docs/engine-api.md for the contract. Import what you need from here.
"""

from gateway.base.versions import VersionInfo
from gateway.engine.build import CompiledRuleSet
from gateway.engine.engine import Engine, LiveRuleSet, RuleSetVersion
from gateway.engine.errors import (
    CompileError,
    CompileFailed,
    CompileResourceError,
    EngineError,
    FactError,
    InvalidRuleSet,
    RuleRuntimeError,
    RuleSetNotFound,
    RunawayRules,
    VersionConflict,
    VersionNotFound,
)
from gateway.engine.results import FireResult
from gateway.engine.session import StatefulSession

__all__ = [
    "CompileError", "CompileFailed", "CompileResourceError", "CompiledRuleSet", "Engine", "EngineError", "FactError", "FireResult",
    "InvalidRuleSet", "LiveRuleSet", "RuleRuntimeError", "RuleSetNotFound", "RuleSetVersion", "RunawayRules",
    "StatefulSession", "VersionConflict", "VersionInfo", "VersionNotFound",
]
