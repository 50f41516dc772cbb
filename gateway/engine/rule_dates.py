"""The dates of ``date-effective`` and ``date-expires`` attributes, checked before a build.

Why: Drools' parser takes any text as such a date. The executable model parses it only when the
built unit is loaded, and a bad one then fails with a bare ``InvocationTargetException`` that names
neither the file nor the attribute, after the whole rule set was compiled. So every such value
(of a rule or of a package header) is read here first, with the very parser the generated code
uses (``PlainRules.ruleDateProblem``), and a bad one is a compile error at its file, line and
column that says which attribute it is and what form a date takes. Nothing is built or deployed.
"""

from __future__ import annotations

import re
from datetime import date
from functools import lru_cache
from typing import Iterable, Protocol

from gateway.base import jvm
from gateway.engine.errors import CompileError

# Comments and strings are skipped (an attribute's name inside them is text); an attribute's name
# followed by a string is one value to check. Anything else is left to Drools' parser.
_SCAN = re.compile(
    r"""
     (?P<skip>//[^\n]*|/\*.*?\*/|"(?:\\.|[^"\\\n])*"|'(?:\\.|[^'\\\n])*')
    |(?<![\w-])(?P<name>date-effective|date-expires)(?![\w-])\s*(?P<value>"(?:\\.|[^"\\\n])*"|'(?:\\.|[^'\\\n])*')?
    """,
    re.X | re.S,
)


class DrlText(Protocol):
    """What is checked: a DRL text, its file, and its lines' places in the author's file."""

    file: str
    drl: str

    def source_line(self, line: int) -> int: ...


def errors(sources: Iterable[DrlText]) -> list[CompileError]:
    """A CompileError for every ``date-effective``/``date-expires`` value of ``sources`` that is
    not a date Drools can read (none when every value is one, or there are none)."""
    out: list[CompileError] = []
    for source in sources:
        if "date-e" not in source.drl:
            continue  # most texts: no scan
        for m in _SCAN.finditer(source.drl):
            if m.group("name") is None or m.group("value") is None:
                continue
            problem = _problem(m.group("value")[1:-1])
            if problem is not None:
                line = source.drl.count("\n", 0, m.start("value")) + 1
                column = m.start("value") - (source.drl.rfind("\n", 0, m.start("value")) + 1) + 1
                out.append(CompileError(source.file, source.source_line(line), column, f"{m.group('name')}: {problem}"))
    return out


@lru_cache(maxsize=256)
def _problem(text: str) -> str | None:
    found = jvm.helper_class("PlainRules").ruleDateProblem(text)
    return None if found is None else str(found)


@lru_cache(maxsize=256)
def day(text: str) -> date | None:
    """The day a ``date-effective``/``date-expires`` value means, or None if it is not a date: read
    as the built rule base reads it (``drools.dateformat``, English month names, any case), so an
    explanation that a rule is not yet effective or has expired judges as the engine does."""
    found = jvm.helper_class("PlainRules").ruleDay(text.strip())
    return None if found is None else date.fromisoformat(str(found))

