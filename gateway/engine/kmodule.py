"""The sessions a rule set declares, read from its ``kmodule.xml`` as KIE does.

Why KIE's file: teams moving from KIE Server already describe their sessions there — a
``<ksession name="…" type="stateful|stateless" default="true" clockType="pseudo|realtime"/>``
per session inside a ``<kbase>`` — and a KIE client reaches them by ``lookup`` name. A rule set
without a ``kmodule.xml`` gets KIE's defaults: a stateful ``defaultKieSession`` and a stateless
``defaultStatelessKieSession``, both default. The one deviation, documented in docs/rest-api.md:
those implied sessions use the pseudo clock (KIE's default is realtime), so replays are
deterministic and ``advance-session-time`` works. A declared ksession is KIE's: ``clockType``
defaults to realtime there too.

One non-KIE attribute is read: ``onDeploy="follow|pin"`` (what the live session does when a new
version is deployed, see :mod:`gateway.engine.sessions`). The kbase's ``packages`` and
``eventProcessingMode`` are not used: a rule set is one KieBase, always in stream mode.

Plain Python (expat): checked with the rule files, errors name the line and column.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import asdict, dataclass
from typing import Any
from xml.parsers import expat

from gateway.engine.errors import CompileError

FILE = "kmodule.xml"
DEFAULT_STATEFUL = "defaultKieSession"
DEFAULT_STATELESS = "defaultStatelessKieSession"
CLOCKS = ("pseudo", "realtime")
POLICIES = ("follow", "pin")
_KSESSION_ATTRS = {"name", "type", "default", "clockType", "onDeploy", "beliefSystem", "scope", "consoleLogger",
                   "fileLogger", "threadedFileLogger", "listeners", "workItemHandlers", "calendars", "channels"}


@dataclass(frozen=True)
class SessionDeclaration:
    """One ksession: its name, whether it keeps facts between calls, its clock, and what it does
    when a new version is deployed (None: the gateway's setting)."""

    name: str
    stateful: bool = True
    clock: str = "pseudo"
    default: bool = False
    on_deploy: str | None = None
    declared: bool = True  # False: one of KIE's implied defaults

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["type"] = "stateful" if self.stateful else "stateless"
        return out


@dataclass(frozen=True)
class Declarations:
    """The sessions of one rule set version, by name."""

    sessions: tuple[SessionDeclaration, ...]

    def get(self, name: str) -> SessionDeclaration | None:
        return next((s for s in self.sessions if s.name == name), None)

    def default(self, stateful: bool) -> SessionDeclaration | None:
        return next((s for s in self.sessions if s.default and s.stateful == stateful), None)

    def names(self) -> list[str]:
        return [s.name for s in self.sessions]

    def to_list(self) -> list[dict[str, Any]]:
        return [s.to_dict() for s in self.sessions]


KIE_DEFAULTS = Declarations((
    SessionDeclaration(DEFAULT_STATEFUL, True, "pseudo", True, None, False),
    SessionDeclaration(DEFAULT_STATELESS, False, "pseudo", True, None, False),
))


class KmoduleError(ValueError):
    """``kmodule.xml`` cannot be used; ``errors`` say where."""

    def __init__(self, errors: list[CompileError]):
        super().__init__(str(errors[0]) if errors else FILE)
        self.errors = errors


def check(files: dict[str, str]) -> list[CompileError]:
    """The problems of the rule set's ``kmodule.xml`` ([] when it has none or it is fine)."""
    try:
        declarations(files)
    except KmoduleError as bad:
        return bad.errors
    return []


_cache: OrderedDict[str, Declarations] = OrderedDict()
_cache_lock = threading.Lock()


def declarations(files: dict[str, str]) -> Declarations:
    """The sessions ``files`` declare, or KIE's defaults; :class:`KmoduleError` when broken."""
    text = files.get(FILE)
    if text is None:
        return KIE_DEFAULTS
    with _cache_lock:
        cached = _cache.get(text)
    if cached is not None:
        return cached
    parsed = parse(text)
    with _cache_lock:
        _cache[text] = parsed
        while len(_cache) > 64:
            _cache.popitem(last=False)
    return parsed


def parse(text: str) -> Declarations:
    """Parses a ``kmodule.xml``; every problem is reported with its line and column."""
    elements: list[tuple[str, dict[str, str], int, int]] = []
    parser = expat.ParserCreate()
    parser.StartElementHandler = lambda tag, attrs: elements.append(
        (tag.rpartition(":")[2], attrs, parser.CurrentLineNumber, parser.CurrentColumnNumber + 1))
    if "<!DOCTYPE" in text or "<!ENTITY" in text:
        raise KmoduleError([CompileError(FILE, _line_of(text, "<!"), 1, "DTDs and entities are not allowed in kmodule.xml")])
    try:
        parser.Parse(text, True)
    except expat.ExpatError as exc:
        raise KmoduleError([CompileError(FILE, exc.lineno, exc.offset + 1, f"not well-formed XML: {expat.ErrorString(exc.code)}")]) from None
    errors: list[CompileError] = []
    if not elements or elements[0][0] != "kmodule":
        line, col = (elements[0][2], elements[0][3]) if elements else (1, 1)
        raise KmoduleError([CompileError(FILE, line, col, "the root element must be <kmodule>")])
    sessions: list[SessionDeclaration] = []
    seen: set[str] = set()
    for tag, attrs, line, col in elements[1:]:
        if tag != "ksession":
            continue
        declaration = _ksession(attrs, line, col, errors)
        if declaration is None:
            continue
        if declaration.name in seen:
            errors.append(CompileError(FILE, line, col, f"ksession '{declaration.name}' is declared twice"))
            continue
        seen.add(declaration.name)
        sessions.append(declaration)
    for stateful in (True, False):
        defaults = [s.name for s in sessions if s.default and s.stateful == stateful]
        if len(defaults) > 1:
            kind = "stateful" if stateful else "stateless"
            line = _line_of(text, f'name="{defaults[1]}"')
            errors.append(CompileError(FILE, line, 1, f"more than one default {kind} ksession: {', '.join(defaults)}"))
    if errors:
        raise KmoduleError(errors)
    return Declarations(tuple(sessions))


def _ksession(attrs: dict[str, str], line: int, col: int, errors: list[CompileError]) -> SessionDeclaration | None:
    name = attrs.get("name", "").strip()
    if not name:
        errors.append(CompileError(FILE, line, col, "a <ksession> needs a name"))
        return None
    unknown = sorted(set(attrs) - _KSESSION_ATTRS)
    if unknown:
        errors.append(CompileError(FILE, line, col, f"ksession '{name}': unknown attribute(s) {', '.join(unknown)}"))
    kind = attrs.get("type", "stateful")
    if kind not in ("stateful", "stateless"):
        errors.append(CompileError(FILE, line, col, f"ksession '{name}': type must be stateful or stateless, not {kind!r}"))
    clock = attrs.get("clockType", "realtime")  # KIE's default for a declared ksession
    if clock not in CLOCKS:
        errors.append(CompileError(FILE, line, col, f"ksession '{name}': clockType must be pseudo or realtime, not {clock!r}"))
    default = attrs.get("default", "false")
    if default not in ("true", "false"):
        errors.append(CompileError(FILE, line, col, f"ksession '{name}': default must be true or false, not {default!r}"))
    policy = attrs.get("onDeploy")
    if policy is not None and policy not in POLICIES:
        errors.append(CompileError(FILE, line, col, f"ksession '{name}': onDeploy must be follow or pin, not {policy!r}"))
    return SessionDeclaration(name, kind != "stateless", clock if clock in CLOCKS else "pseudo", default == "true",
                              policy if policy in POLICIES else None)


def _line_of(text: str, needle: str) -> int:
    index = text.find(needle)
    return 1 if index < 0 else text.count("\n", 0, index) + 1
