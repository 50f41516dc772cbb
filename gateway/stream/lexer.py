"""A small SPARQL/C-SPARQL tokenizer that keeps line and column of every token.

Why our own: the C-SPARQL extensions (REGISTER, FROM STREAM … [RANGE …]) must be found and cut out
before a standard SPARQL engine sees the query, and every error must point at line:column. Only
the token classes that matter for that are distinguished; the SPARQL engine checks the rest.
"""

from __future__ import annotations

import re
from dataclasses import dataclass


class QueryParseError(ValueError):
    """A query that cannot be registered; ``line``/``column`` are 1-based (0 = unknown)."""

    def __init__(self, message: str, line: int = 0, column: int = 0) -> None:
        where = f"line {line}, column {column}: " if line else ""
        super().__init__(where + message)
        self.message = message
        self.line = line
        self.column = column

    def to_dict(self) -> dict[str, object]:
        return {"message": self.message, "line": self.line, "column": self.column}


@dataclass(frozen=True)
class Token:
    kind: str  # IRI, PNAME, VAR, STRING, NUMBER, DURATION (ISO 8601, e.g. PT10S), NAME, PUNCT
    text: str
    start: int  # offset in the source
    end: int
    line: int
    column: int

    def upper(self) -> str:
        return self.text.upper()


_PN_CHARS = r"[A-Za-z0-9_\u00B7\u00C0-\uFFFF-]"
_TOKEN_RE = re.compile(
    r"""
    (?P<WS>\s+)
  | (?P<COMMENT>\#[^\n]*)
  | (?P<STRING>\"\"\"(?:[^"\\]|\\.|"(?!""))*\"\"\"|'''(?:[^'\\]|\\.|'(?!''))*'''
              |"(?:[^"\\\n]|\\.)*"|'(?:[^'\\\n]|\\.)*')
  | (?P<IRI><[^<>"{}|^`\\\s]*>)
  | (?P<VAR>[?$][A-Za-z0-9_\u00B7\u00C0-\uFFFF]+)
  | (?P<NUMBER>(?:\d+(?:\.\d+)?|\.\d+)(?:[eE][+-]?\d+)?)
  | (?P<PNAME>(?:[A-Za-z\u00C0-\uFFFF](?:[A-Za-z0-9_.\u00B7\u00C0-\uFFFF-]*[A-Za-z0-9_\u00B7\u00C0-\uFFFF-])?)?:
              (?:(?:[A-Za-z0-9_:\u00C0-\uFFFF]|%[0-9A-Fa-f]{2}|\\[-_~.!$&'()*+,;=/?\#@%])
                 (?:(?:[A-Za-z0-9_:.\u00B7\u00C0-\uFFFF-]|%[0-9A-Fa-f]{2}|\\[-_~.!$&'()*+,;=/?\#@%])*
                  (?:[A-Za-z0-9_:\u00B7\u00C0-\uFFFF-]|%[0-9A-Fa-f]{2}))?)?)
  | (?P<BNODE>_:[A-Za-z0-9_\u00C0-\uFFFF][A-Za-z0-9_.\u00B7\u00C0-\uFFFF-]*)
  | (?P<DURATION>P(?=[0-9]|T[0-9])(?:[0-9]+D)?(?:T(?=[0-9])(?:[0-9]+H)?(?:[0-9]+M)?(?:[0-9]+(?:\.[0-9]+)?S)?)?
                (?![A-Za-z0-9_]))
  | (?P<NAME>[A-Za-z_][A-Za-z0-9_]*)
  | (?P<PUNCT>\^\^|&&|\|\||<=|>=|!=|[{}()\[\].,;*+\-/=<>!^|@a])
    """,
    re.VERBOSE,
)


def tokenize(text: str) -> list[Token]:
    """All tokens of ``text``; an unknown character raises :class:`QueryParseError` at its place."""
    tokens: list[Token] = []
    pos, line, line_start = 0, 1, 0
    while pos < len(text):
        match = _TOKEN_RE.match(text, pos)
        if match is None or match.end() == pos:
            raise QueryParseError(f"unexpected character {text[pos]!r}", line, pos - line_start + 1)
        kind = match.lastgroup or "PUNCT"
        value = match.group()
        if kind not in ("WS", "COMMENT"):
            if kind == "BNODE":
                kind = "PNAME"
            tokens.append(Token(kind, value, pos, match.end(), line, pos - line_start + 1))
        newlines = value.count("\n")
        if newlines:
            line += newlines
            line_start = pos + value.rfind("\n") + 1
        pos = match.end()
    return tokens


def position(text: str, offset: int) -> tuple[int, int]:
    """1-based (line, column) of an offset."""
    line = text.count("\n", 0, offset) + 1
    return line, offset - (text.rfind("\n", 0, offset) + 1) + 1
