"""C-SPARQL text → a registered continuous query: name, windows, static graphs, parameters and the
standard SPARQL that is evaluated on each window.

Accepted syntax (C-SPARQL, Barbieri et al. 2010, plus one directive of ours)::

    PARAM ?distance_to_entrance FROM ONTOLOGY "SELECT ?d WHERE { … }"   # optional, repeatable
    PARAM ?threshold = 0.1                                              # a constant parameter
    REGISTER QUERY <name> AS            (or REGISTER STREAM <name> AS; COMPUTED EVERY … is ignored)
    PREFIX …
    SELECT … | CONSTRUCT … | ASK …
    FROM STREAM <iri> [RANGE 3s STEP 1s]      units: ms, s, m, h, d; or TUMBLING instead of STEP
    FROM STREAM <iri> [RANGE TRIPLES 100]     a count window: the last 100 triples of the stream
    FROM <iri>                                a static background graph (registered by name)
    FROM NAMED <iri>                          a static graph available to GRAPH <iri> { … }
    WHERE { … f:timestamp(?s, ?p, ?o) … }

Why blanking instead of rewriting: the C-SPARQL-only parts are replaced by spaces of the same
length (newlines kept), so the SPARQL engine's error positions are the positions in the user's
text, and parameters are substituted as literals only at evaluation time.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from decimal import Decimal, InvalidOperation

from gateway.stream.lexer import QueryParseError, Token, tokenize

UNITS_MS = {"ms": 1, "s": 1000, "m": 60_000, "h": 3_600_000, "d": 86_400_000}
FORMS = ("SELECT", "CONSTRUCT", "ASK", "DESCRIBE")
MAX_TRIPLES_WINDOW = 10_000_000


@dataclass(frozen=True)
class WindowSpec:
    """The window a query keeps over one stream: time-based (range/step) or count-based (triples)."""

    stream: str
    range_ms: int | None = None
    step_ms: int | None = None
    triples: int | None = None

    @property
    def is_time(self) -> bool:
        return self.range_ms is not None

    def to_dict(self) -> dict[str, object]:
        return {"stream": self.stream, "range_ms": self.range_ms, "step_ms": self.step_ms,
                "triples": self.triples}


@dataclass(frozen=True)
class ParamSpec:
    """A query parameter: bound from the ontology by ``sparql`` or set to a constant ``value``
    (SPARQL literal/IRI text)."""

    name: str
    sparql: str | None = None
    value: str | None = None

    def to_dict(self) -> dict[str, object]:
        return {"name": self.name, "sparql": self.sparql, "value": self.value}


@dataclass
class ContinuousQuery:
    """A parsed C-SPARQL query. ``sparql`` is standard SPARQL with the same line/column layout."""

    name: str
    kind: str  # "QUERY" or "STREAM"
    form: str  # SELECT, CONSTRUCT, ASK, DESCRIBE
    text: str
    sparql: str
    windows: list[WindowSpec]
    static_graphs: list[str] = field(default_factory=list)
    named_graphs: list[str] = field(default_factory=list)
    params: list[ParamSpec] = field(default_factory=list)
    var_spans: dict[str, list[tuple[int, int]]] = field(default_factory=dict)

    @property
    def step_ms(self) -> int | None:
        """How often the query is evaluated (event time); None = on every message (count windows)."""
        steps = [w.step_ms for w in self.windows if w.is_time]
        return steps[0] if steps else None

    @property
    def streams(self) -> list[str]:
        return [w.stream for w in self.windows]

    def executable(self, values: dict[str, str]) -> str:
        """The SPARQL text with each parameter variable replaced by its value's SPARQL text."""
        spans = sorted((s, e, values[name]) for name, lst in self.var_spans.items()
                       if name in values for s, e in lst)
        out, pos = [], 0
        for start, end, value in spans:
            out.append(self.sparql[pos:start])
            out.append(value)
            pos = end
        out.append(self.sparql[pos:])
        return "".join(out)


class _Cursor:
    """Walks the token list; ``expect`` raises a positioned error."""

    def __init__(self, text: str, tokens: list[Token]) -> None:
        self.text, self.tokens, self.i = text, tokens, 0

    def peek(self, ahead: int = 0) -> Token | None:
        j = self.i + ahead
        return self.tokens[j] if j < len(self.tokens) else None

    def next(self, what: str) -> Token:
        tok = self.peek()
        if tok is None:
            line = self.text.count("\n") + 1
            raise QueryParseError(f"unexpected end of query, expected {what}", line,
                                  len(self.text) - self.text.rfind("\n"))
        self.i += 1
        return tok

    def expect_word(self, *words: str) -> Token:
        tok = self.next(" or ".join(words))
        if tok.upper() not in words:
            raise QueryParseError(f"expected {' or '.join(words)}, found {tok.text!r}", tok.line, tok.column)
        return tok

    def expect_kind(self, kind: str, what: str) -> Token:
        tok = self.next(what)
        if tok.kind != kind:
            raise QueryParseError(f"expected {what}, found {tok.text!r}", tok.line, tok.column)
        return tok


def parse_query(text: str, extra_params: list[ParamSpec] | None = None) -> ContinuousQuery:
    """Parse C-SPARQL ``text``; raises :class:`QueryParseError` with line/column on any error."""
    if not text or not text.strip():
        raise QueryParseError("the query is empty", 1, 1)
    tokens = tokenize(text)
    cur = _Cursor(text, tokens)
    blank: list[tuple[int, int]] = []
    params: list[ParamSpec] = []

    while cur.peek() is not None and cur.peek().upper() == "PARAM":  # type: ignore[union-attr]
        start = cur.next("PARAM").start
        params.append(_parse_param(cur))
        blank.append((start, cur.tokens[cur.i - 1].end))

    first = cur.peek()
    if first is None or first.upper() != "REGISTER":
        tok = first or tokens[-1]
        raise QueryParseError("a continuous query starts with REGISTER QUERY <name> AS", tok.line, tok.column)
    start = cur.next("REGISTER").start
    kind = cur.expect_word("QUERY", "STREAM").upper()
    name_tok = cur.next("a query name")
    if name_tok.kind not in ("NAME", "PNAME", "IRI"):
        raise QueryParseError(f"expected a query name, found {name_tok.text!r}", name_tok.line, name_tok.column)
    name = name_tok.text.strip("<>")
    if not re.fullmatch(r"[A-Za-z0-9_.:/#-]{1,200}", name):
        raise QueryParseError(f"invalid query name {name!r}", name_tok.line, name_tok.column)
    if cur.peek() is not None and cur.peek().upper() == "COMPUTED":  # type: ignore[union-attr]
        cur.next("COMPUTED")
        cur.expect_word("EVERY")
        _duration(cur)
    cur.expect_word("AS")
    blank.append((start, cur.tokens[cur.i - 1].end))

    prefixes: dict[str, str] = {}
    windows: list[WindowSpec] = []
    static_graphs: list[str] = []
    named_graphs: list[str] = []
    form: str | None = None
    body_start = cur.i
    while cur.peek() is not None:
        tok = cur.next("a token")
        word = tok.upper()
        if tok.kind == "NAME" and word == "PREFIX":
            pname = cur.expect_kind("PNAME", "a prefix name like ex:")
            iri = cur.expect_kind("IRI", "the prefix IRI <…>")
            if not pname.text.endswith(":"):
                raise QueryParseError(f"a prefix declaration needs 'name:', found {pname.text!r}",
                                      pname.line, pname.column)
            prefixes[pname.text[:-1]] = iri.text[1:-1]
        elif tok.kind == "NAME" and word in FORMS and form is None:
            form = word
        elif tok.kind == "NAME" and word == "FROM":
            nxt = cur.peek()
            if nxt is not None and nxt.upper() == "STREAM":
                cur.next("STREAM")
                windows.append(_parse_stream(cur, prefixes))
            elif nxt is not None and nxt.upper() == "NAMED":
                cur.next("NAMED")
                named_graphs.append(_iri(cur, prefixes, "a graph IRI"))
            else:
                static_graphs.append(_iri(cur, prefixes, "a graph IRI"))
            blank.append((tok.start, cur.tokens[cur.i - 1].end))
    if form is None:
        tok = cur.tokens[body_start] if body_start < len(tokens) else tokens[-1]
        raise QueryParseError("expected SELECT, CONSTRUCT, ASK or DESCRIBE", tok.line, tok.column)
    if not windows:
        raise QueryParseError("a continuous query needs at least one FROM STREAM <iri> [RANGE …]",
                              tokens[-1].line, tokens[-1].column)
    time_steps = {w.step_ms for w in windows if w.is_time}
    if len(time_steps) > 1:
        raise QueryParseError(f"all time windows of a query must share one STEP, found {sorted(time_steps)} ms",
                              name_tok.line, name_tok.column)

    for tok in tokens[body_start:]:
        if tok.kind == "PNAME" and not tok.text.startswith("_:"):
            prefix = tok.text.split(":", 1)[0]
            if prefix not in prefixes:
                raise QueryParseError(f"unknown prefix {prefix!r} in {tok.text!r} (declare it with PREFIX)",
                                      tok.line, tok.column)

    all_params = params + list(extra_params or [])
    seen: set[str] = set()
    for p in all_params:
        if p.name in seen:
            raise QueryParseError(f"parameter ?{p.name} is defined twice", 1, 1)
        seen.add(p.name)
    var_spans: dict[str, list[tuple[int, int]]] = {}
    for tok in tokens[body_start:]:
        if tok.kind == "VAR" and tok.text[1:] in seen:
            var_spans.setdefault(tok.text[1:], []).append((tok.start, tok.end))

    return ContinuousQuery(
        name=name, kind=kind, form=form, text=text, sparql=_blank_out(text, blank), windows=windows,
        static_graphs=static_graphs, named_graphs=named_graphs, params=all_params, var_spans=var_spans,
    )


def _blank_out(text: str, spans: list[tuple[int, int]]) -> str:
    chars = list(text)
    for start, end in spans:
        for k in range(start, end):
            if chars[k] not in "\r\n":
                chars[k] = " "
    return "".join(chars)


def _iri(cur: _Cursor, prefixes: dict[str, str], what: str) -> str:
    tok = cur.next(what)
    if tok.kind == "IRI":
        return tok.text[1:-1]
    if tok.kind == "PNAME":
        prefix, local = tok.text.split(":", 1)
        if prefix not in prefixes:
            raise QueryParseError(f"unknown prefix {prefix!r} in {tok.text!r}", tok.line, tok.column)
        return prefixes[prefix] + local
    raise QueryParseError(f"expected {what}, found {tok.text!r}", tok.line, tok.column)


def _parse_stream(cur: _Cursor, prefixes: dict[str, str]) -> WindowSpec:
    stream = _iri(cur, prefixes, "the stream IRI <…>")
    open_tok = cur.next("[RANGE …]")
    if open_tok.text != "[":
        raise QueryParseError(f"expected a window [RANGE …] after the stream, found {open_tok.text!r}",
                              open_tok.line, open_tok.column)
    range_tok = cur.expect_word("RANGE")
    nxt = cur.peek()
    if nxt is not None and nxt.upper() == "TRIPLES":
        cur.next("TRIPLES")
        num = cur.expect_kind("NUMBER", "a number of triples")
        if not num.text.isdigit() or not 0 < int(num.text) <= MAX_TRIPLES_WINDOW:
            raise QueryParseError(f"TRIPLES needs an integer between 1 and {MAX_TRIPLES_WINDOW}",
                                  num.line, num.column)
        _close_window(cur)
        return WindowSpec(stream=stream, triples=int(num.text))
    range_ms = _duration(cur)
    step_tok = cur.expect_word("STEP", "TUMBLING")
    step_ms = range_ms if step_tok.upper() == "TUMBLING" else _duration(cur)
    if range_ms <= 0:
        raise QueryParseError("RANGE must be greater than zero", range_tok.line, range_tok.column)
    if step_ms <= 0:
        raise QueryParseError("STEP must be greater than zero", step_tok.line, step_tok.column)
    if step_ms > range_ms:
        raise QueryParseError(f"STEP ({step_ms} ms) is larger than RANGE ({range_ms} ms): data between "
                              "windows would be skipped", step_tok.line, step_tok.column)
    _close_window(cur)
    return WindowSpec(stream=stream, range_ms=range_ms, step_ms=step_ms)


def _close_window(cur: _Cursor) -> None:
    tok = cur.next("]")
    if tok.text != "]":
        raise QueryParseError(f"expected ] to close the window, found {tok.text!r}", tok.line, tok.column)


def _duration(cur: _Cursor) -> int:
    """``3s``, ``500ms``, ``1.5m`` … as whole milliseconds."""
    num = cur.expect_kind("NUMBER", "a duration like 3s")
    unit = cur.next("a time unit (ms, s, m, h, d)")
    if unit.text not in UNITS_MS:
        raise QueryParseError(f"expected a time unit (ms, s, m, h, d) right after {num.text}, found {unit.text!r}",
                              unit.line, unit.column)
    try:
        value = Decimal(num.text) * UNITS_MS[unit.text]
    except InvalidOperation:
        raise QueryParseError(f"invalid number {num.text!r}", num.line, num.column) from None
    if value != value.to_integral_value():
        raise QueryParseError(f"{num.text}{unit.text} is not a whole number of milliseconds", num.line, num.column)
    return int(value)


def _parse_param(cur: _Cursor) -> ParamSpec:
    var = cur.expect_kind("VAR", "a parameter variable like ?distance_to_entrance")
    tok = cur.next("FROM ONTOLOGY \"…\" or = value")
    if tok.upper() == "FROM":
        cur.expect_word("ONTOLOGY")
        query = cur.expect_kind("STRING", "a quoted SPARQL query")
        return ParamSpec(name=var.text[1:], sparql=_unquote(query.text))
    if tok.text == "=":
        value = cur.next("a value")
        if value.kind not in ("NUMBER", "STRING", "IRI") and value.text.lower() not in ("true", "false"):
            raise QueryParseError(f"a parameter value must be a number, string, IRI or boolean, found "
                                  f"{value.text!r}", value.line, value.column)
        return ParamSpec(name=var.text[1:], value=value.text)
    raise QueryParseError(f"expected FROM ONTOLOGY \"…\" or = value, found {tok.text!r}", tok.line, tok.column)


def _unquote(text: str) -> str:
    if text[:3] in ('"""', "'''"):
        body = text[3:-3]
    else:
        body = text[1:-1]
    return re.sub(r"\\(.)", lambda m: {"n": "\n", "t": "\t"}.get(m.group(1), m.group(1)), body)
