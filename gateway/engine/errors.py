"""Errors of the rules engine, each with a JSON form for the REST API.

Why structured: rule authors need *where* (file, line, column, field) as much as *what*; a client
firing rules needs to know which fact and field it got wrong.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any


def more_errors(n: int) -> str:
    """The tail after the first error's message, naming what the rest are: a bare "(and 1 more)"
    after a list of allowed keys read as one more key."""
    return f" (and {n} more error{'s' if n != 1 else ''})" if n > 0 else ""


@dataclass(frozen=True)
class CompileError:
    """One compile problem. Lines and columns are 1-based; 0 means unknown.

    A problem in a decision table (``.csv``/``.xlsx``) also names its ``sheet`` and ``cell``
    (``"C7"``); ``line`` and ``column`` are then the cell's row and column numbers, so editors that
    only know positions still land on the right place.
    """

    file: str
    line: int
    column: int
    message: str
    sheet: str = ""
    cell: str = ""

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        if not self.cell:  # plain text files keep the four fields they always had
            out.pop("sheet")
            out.pop("cell")
        return out

    @property
    def where(self) -> str:
        """``file:line:col`` or, in a decision table, ``file!Sheet!C7``."""
        if self.cell:
            return f"{self.file}!{self.sheet}!{self.cell}" if self.sheet else f"{self.file}!{self.cell}"
        return f"{self.file}:{self.line}:{self.column}"

    def __str__(self) -> str:
        return f"{self.where}: {self.message}"


class EngineError(Exception):
    """Base of all engine errors."""

    kind = "engine"

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind}


class InvalidRuleSet(EngineError):
    """The rule set itself is unacceptable (bad name, bad file names, too large, empty)."""

    kind = "invalid"

    def __init__(self, message: str, errors: list[CompileError] | None = None):
        super().__init__(message)
        self.errors = errors or []

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind, "errors": [e.to_dict() for e in self.errors]}


class CompileFailed(EngineError):
    """The rule set does not compile; nothing was deployed."""

    kind = "compile"

    def __init__(self, errors: list[CompileError]):
        self.errors = errors
        first = errors[0] if errors else None
        more = more_errors(len(errors) - 1)
        super().__init__(f"rule set does not compile: {first}{more}")

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind, "errors": [e.to_dict() for e in self.errors]}


class PolicyRefused(CompileFailed):
    """The rule policy refuses the rule set for this principal (an ``author``): it names a class or
    makes a call only a ``developer`` may deploy (:mod:`gateway.engine.policy`). Nothing was
    compiled, nothing ran, and what serves is untouched. A 422, like a compile error."""

    kind = "policy"

    def __init__(self, errors: list[CompileError]):
        super().__init__(errors)
        more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
        EngineError.__init__(self, f"rule set refused by the rule policy: {errors[0] if errors else ''}{more}")


class BuildCancelled(EngineError):
    """Someone cancelled the build (a build job) before it finished; nothing was deployed.

    Raised by a progress callback between units: the build stops starting units, a unit that is
    compiling finishes unused, and what serves is untouched."""

    kind = "cancelled"


# How the JVM running out of memory shows in the text of an error. JPype's own "Fatal error
# occurred" stands in for the Java error when JPype cannot build that error's Python side, which,
# in a build, is the heap being exhausted (1 build in 6 with a 32 MB heap ended so).
OUT_OF_MEMORY_MARKERS = ("OutOfMemoryError", "Java heap space", "GC overhead limit exceeded", "Metaspace",
                         "Fatal error occurred")


def says_out_of_memory(text: str) -> bool:
    """Whether an error's text says the JVM ran out of memory (see OUT_OF_MEMORY_MARKERS)."""
    return any(marker in text for marker in OUT_OF_MEMORY_MARKERS)


class CompileResourceError(EngineError):
    """Compiling ran out of memory or time: a server-side limit, not a fault of the rule text.

    Nothing was deployed and what serves is untouched. ``setting`` names what an operator raises
    (e.g. ``PRINTEPS_JVM_HEAP``); the REST API answers 503.
    """

    kind = "resources"

    def __init__(self, reason: str, message: str, setting: str, limit: str | None = None):
        self.reason = reason  # "memory" | "time"
        self.setting = setting
        self.limit = limit
        super().__init__(f"{message}; this is a server limit, not an error in the rules: raise {setting}")

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind, "reason": self.reason, "setting": self.setting, "limit": self.limit}


class FactError(EngineError):
    """Facts were refused (unknown type/field, wrong value type); nothing was fired."""

    kind = "facts"

    def __init__(self, errors: list[dict[str, Any]], total: int | None = None):
        self.errors = errors
        self.total = total if total is not None else len(errors)
        first = errors[0] if errors else {}
        where = f"fact {first.get('index')}" if first.get("index", -1) >= 0 else "facts"
        if first.get("type"):
            where += f" ({first['type']}"
            where += f" '{first['id']}')" if first.get("id") else ")"
        more = more_errors(self.total - 1)
        super().__init__(f"{where}: {first.get('message', 'invalid facts')}{more}")

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind, "errors": self.errors, "error_count": self.total}


class RunawayRules(EngineError):
    """The fire limit was reached while rules were still activated (a loop); nothing is returned."""

    kind = "runaway"

    def __init__(self, limit: int, counts: dict[str, int]):
        self.limit = limit
        self.counts = counts
        top = sorted(counts.items(), key=lambda kv: -kv[1])[:3]
        tops = ", ".join(f"'{r}' {n}x" for r, n in top)
        super().__init__(f"stopped after {limit} rule firings (a rule loop?): {tops}")

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind, "limit": self.limit, "counts": self.counts}


class RuleRuntimeError(EngineError):
    """A then-part threw an exception while firing."""

    kind = "runtime"

    def __init__(self, rule: str | None, message: str):
        self.rule = rule
        super().__init__(f"rule '{rule}' failed: {message}" if rule else f"firing failed: {message}")

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind, "rule": self.rule}


class RuleSetNotFound(EngineError, LookupError):
    kind = "not_found"

    def __init__(self, name: str):
        self.name = name
        super().__init__(f"no rule set named '{name}'")


class VersionNotFound(EngineError):
    kind = "not_found"

    def __init__(self, name: str, version: int):
        super().__init__(f"rule set '{name}' has no version {version}")


class VersionConflict(EngineError):
    """A deploy was based on a version that is no longer current (someone else deployed)."""

    kind = "conflict"

    def __init__(self, name: str, base: int, current: int):
        self.current = current
        super().__init__(
            f"base version changed: rule set '{name}' is at version {current}, the edit was based on {base}"
        )

    def to_dict(self) -> dict[str, Any]:
        return {"error": "base version changed", "kind": self.kind, "current": self.current, "detail": str(self)}


class ScenariosFailed(EngineError):
    """The rule set's own test scenarios (``tests/*.yaml``) are red: a deploy refuses it unless forced."""

    kind = "scenarios"

    def __init__(self, message: str, errors: list[dict[str, Any]], report: dict[str, Any]):
        super().__init__(message)
        self.errors = errors
        self.report = report

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind, "errors": self.errors, "report": self.report}


class FireTimeout(EngineError):
    """A fire ran past ``engine.fire_timeout_s`` and was halted (``KieSession.halt()``) before its
    next rule firing; its answer and any decision are dropped (503)."""

    kind = "timeout"
    setting = "engine.fire_timeout_s"

    def __init__(self, ruleset: str | None, limit_s: float, fired: int = 0) -> None:
        who = f"rule set {ruleset!r}" if ruleset else "the rule set"
        super().__init__(f"the fire of {who} was stopped after its time limit of {limit_s:g} s "
                         f"({fired} rules had fired; nothing was recorded); raise {self.setting} if it needs longer")
        self.ruleset, self.limit, self.fired = ruleset, limit_s, fired

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind, "ruleset": self.ruleset, "limit": self.limit,
                "setting": self.setting}


class Overloaded(EngineError):
    """A fire refused before it started: its rule set's queue is full (``reason`` ``queue_full``,
    429) or it would wait, or has waited, longer than allowed (``waited``, 503). ``retry_after_s``
    is when a retry has a fair chance (sent as ``Retry-After``)."""

    kind = "overloaded"

    def __init__(self, ruleset: str, reason: str, limit: float, setting: str, retry_after_s: int, message: str) -> None:
        super().__init__(message)
        self.ruleset, self.reason, self.limit, self.setting = ruleset, reason, limit, setting
        self.retry_after_s = retry_after_s

    @property
    def status(self) -> int:
        return 429 if self.reason == "queue_full" else 503

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind, "reason": self.reason, "ruleset": self.ruleset,
                "limit": self.limit, "setting": self.setting, "retry_after_s": self.retry_after_s}
