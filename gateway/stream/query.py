"""C-SPARQL / RSP-QL text → a registered continuous query: name, windows, report policy, stream
operator, static graphs, parameters and the standard SPARQL that is evaluated on each window.

Accepted syntax (C-SPARQL, Barbieri et al. 2010, with the RSP-QL additions of Dell'Aglio et al.
and two directives of ours; see docs/streams.md for the exact semantics)::

    PARAM ?distance_to_entrance FROM ONTOLOGY "SELECT ?d WHERE { … }"   # optional, repeatable
    PARAM ?threshold = 0.1                                              # a constant parameter
    REGISTER QUERY <name> [REPORT <policy> [AND <policy>]] [COMPUTED EVERY 5s] AS
    REGISTER STREAM <name> … AS CONSTRUCT …   # the results form an RDF stream named <name>
    PREFIX …
    SELECT [RSTREAM|ISTREAM|DSTREAM] … | CONSTRUCT [RSTREAM|ISTREAM|DSTREAM] { … } | ASK | DESCRIBE
    FROM STREAM <iri> [RANGE 3s STEP 1s]      units ms, s, m, h, d or ISO 8601 (PT3S); TUMBLING
    FROM STREAM <iri> [RANGE TRIPLES 100]     a count window: the last 100 triples of the stream
    FROM STREAM <iri> [RANGE ?param STEP 1s]  the range is a parameter (e.g. from the ontology)
    FROM NAMED WINDOW <w> ON [STREAM] <iri> [RANGE …]   a named window, used as WINDOW <w> { … }
    FROM NAMED STREAM <iri> [RANGE …]         a named window named like its stream (C-SPARQL)
    FROM <iri>                                a static background graph (registered by name)
    FROM NAMED <iri>                          a static graph available to GRAPH <iri> { … }
    WHERE { … f:timestamp(?s, ?p, ?o) … }

    <policy> = [ON] WINDOW CLOSE | [ON] CONTENT CHANGE | NON EMPTY | PERIODIC <duration>

Why blanking instead of rewriting: the C-SPARQL-only parts are replaced by spaces of the same
length (newlines kept) and ``WINDOW <w> {`` by ``GRAPH  <w> {``, so the SPARQL engine's error
positions are the positions in the user's text, and parameters are substituted as literals only at
evaluation time.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from decimal import Decimal, InvalidOperation

from gateway.stream.lexer import QueryParseError, Token, tokenize

UNITS_MS = {"ms": 1, "s": 1000, "m": 60_000, "h": 3_600_000, "d": 86_400_000}
FORMS = ("SELECT", "CONSTRUCT", "ASK", "DESCRIBE")
R2S = ("RSTREAM", "ISTREAM", "DSTREAM")
MAX_TRIPLES_WINDOW = 10_000_000
CSPARQL_FN = "http://larkc.eu/csparql/sparql/jena/ext#"
SUPPORTED_FUNCTIONS = {CSPARQL_FN + "timestamp"}
_ISO_DURATION = re.compile(r"^P(?:(\d+)D)?(?:T(?:(\d+)H)?(?:(\d+)M)?(?:(\d+(?:\.\d+)?)S)?)?$")


@dataclass(frozen=True)
class WindowSpec:
    """A window over one stream: time-based (range/step) or count-based (triples).

    ``name`` is None for the windows that form the default graph (``FROM STREAM``) and the window
    IRI for a named window (``FROM NAMED WINDOW <name> ON <stream>``). ``range_param`` names the
    parameter whose value is the range (``[RANGE ?p STEP 1s]``); ``range_ms`` is then None until
    the engine binds it."""

    stream: str
    range_ms: int | None = None
    step_ms: int | None = None
    triples: int | None = None
    name: str | None = None
    range_param: str | None = None
    line: int = field(default=0, compare=False)
    column: int = field(default=0, compare=False)
    range_at: tuple[int, int] = field(default=(0, 0), compare=False)  # where ``?param`` is written

    @property
    def is_time(self) -> bool:
        return self.step_ms is not None

    def to_dict(self) -> dict[str, object]:
        return {"stream": self.stream, "range_ms": self.range_ms, "step_ms": self.step_ms,
                "triples": self.triples, "name": self.name, "range_param": self.range_param}


@dataclass(frozen=True)
class ReportPolicy:
    """When a query's windows are reported (RSP-QL / SECRET report strategies, Botan et al.).

    ``trigger``: ``window_close`` (default: every window, when it closes), ``content_change``
    (whenever the content of the current window changed since the last report, checked at every
    message and heartbeat) or ``periodic`` (at every multiple of ``period_ms``, epoch-aligned).
    ``non_empty`` adds the condition that the window content is not empty (C-SPARQL's behaviour
    is ``window_close`` + ``non_empty``)."""

    trigger: str = "window_close"
    non_empty: bool = False
    period_ms: int | None = None

    def to_dict(self) -> dict[str, object]:
        return {"trigger": self.trigger, "non_empty": self.non_empty, "period_ms": self.period_ms}

    def describe(self) -> str:
        text = {"window_close": "ON WINDOW CLOSE", "content_change": "ON CONTENT CHANGE",
                "periodic": f"PERIODIC {self.period_ms}ms"}[self.trigger]
        return text + (" AND NON EMPTY" if self.non_empty else "")

    @classmethod
    def parse(cls, text: str) -> ReportPolicy:
        """A policy written as in the REPORT clause (``"content change"``, ``"periodic 5s"``,
        ``"window close and non empty"``); raises QueryParseError (line 1, column in ``text``)."""
        tokens = tokenize(text)
        if not tokens:
            raise QueryParseError("empty report policy", 1, 1)
        cur = _Cursor(text, tokens)
        policy = _parse_policies(cur)
        extra = cur.peek()
        if extra is not None:
            raise QueryParseError(f"unexpected {extra.text!r} in the report policy", extra.line, extra.column)
        return policy


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
    """A parsed continuous query. ``sparql`` is standard SPARQL with the same line/column layout."""

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
    report: ReportPolicy = field(default_factory=ReportPolicy)
    r2s: str = "RSTREAM"
    output_stream: str | None = None  # the stream a REGISTER STREAM query produces
    ordered: bool = False  # ORDER BY: keep the engine's row order

    @property
    def step_ms(self) -> int | None:
        """The window step (event time); None = evaluated on every message (only count windows)."""
        steps = [w.step_ms for w in self.windows if w.is_time]
        return steps[0] if steps else None

    @property
    def streams(self) -> list[str]:
        """The input streams, each once, in order of appearance."""
        return list(dict.fromkeys(w.stream for w in self.windows))

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

    def peek_word(self, ahead: int = 0) -> str:
        tok = self.peek(ahead)
        return tok.upper() if tok is not None else ""

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

    @property
    def last(self) -> Token:
        return self.tokens[self.i - 1]


def parse_query(text: str, extra_params: list[ParamSpec] | None = None,
                report: ReportPolicy | None = None) -> ContinuousQuery:
    """Parse ``text``; raises :class:`QueryParseError` with line/column on any error.

    ``report`` (a registration option) overrides the query's REPORT clause."""
    if not text or not text.strip():
        raise QueryParseError("the query is empty", 1, 1)
    tokens = tokenize(text)
    cur = _Cursor(text, tokens)
    blank: list[tuple[int, int]] = []
    params: list[ParamSpec] = []

    while cur.peek_word() == "PARAM":
        start = cur.next("PARAM").start
        params.append(_parse_param(cur))
        blank.append((start, cur.last.end))

    first = cur.peek()
    if first is None or first.upper() != "REGISTER":
        tok = first or tokens[-1]
        raise QueryParseError("a continuous query starts with REGISTER QUERY <name> AS", tok.line, tok.column)
    start = cur.next("REGISTER").start
    kind_tok = cur.next("QUERY or STREAM")
    kind = kind_tok.upper()
    if kind in R2S:
        raise QueryParseError(f"REGISTER {kind} is not supported: write REGISTER STREAM <name> AS CONSTRUCT "
                              f"{kind} {{ … }} (or SELECT {kind})", kind_tok.line, kind_tok.column)
    if kind not in ("QUERY", "STREAM"):
        raise QueryParseError(f"expected QUERY or STREAM, found {kind_tok.text!r}", kind_tok.line, kind_tok.column)
    name_tok = cur.next("a query name")
    if name_tok.kind not in ("NAME", "PNAME", "IRI"):
        raise QueryParseError(f"expected a query name, found {name_tok.text!r}", name_tok.line, name_tok.column)
    name = name_tok.text.strip("<>")
    if not re.fullmatch(r"[A-Za-z0-9_.:/#-]{1,200}", name):
        raise QueryParseError(f"invalid query name {name!r}", name_tok.line, name_tok.column)
    policy: ReportPolicy | None = None
    computed: tuple[int, Token] | None = None
    while cur.peek_word() in ("REPORT", "COMPUTED"):
        tok = cur.next("REPORT or COMPUTED")
        if tok.upper() == "REPORT":
            if policy is not None:
                raise QueryParseError("REPORT is given twice", tok.line, tok.column)
            policy = _parse_policies(cur)
        else:
            cur.expect_word("EVERY")
            computed = (_duration(cur), tok)
    if computed is not None:  # C-SPARQL's COMPUTED EVERY d is the periodic report policy
        if policy is not None and policy.trigger != "periodic":
            raise QueryParseError(f"COMPUTED EVERY conflicts with REPORT {policy.describe()}",
                                  computed[1].line, computed[1].column)
        if policy is not None and policy.period_ms != computed[0]:
            raise QueryParseError("COMPUTED EVERY and REPORT PERIODIC give different periods",
                                  computed[1].line, computed[1].column)
        policy = ReportPolicy("periodic", policy.non_empty if policy else False, computed[0])
    cur.expect_word("AS")
    blank.append((start, cur.last.end))

    prefixes: dict[str, str] = {}
    windows: list[WindowSpec] = []
    static_graphs: list[str] = []
    named_graphs: list[str] = []
    form: str | None = None
    form_tok: Token | None = None
    r2s = "RSTREAM"
    rewrites: list[tuple[int, int, str]] = []
    window_refs: list[tuple[Token, str]] = []
    ordered = False
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
            form, form_tok = word, tok
            if cur.peek_word() in R2S:
                op = cur.next("a stream operator")
                r2s = op.upper()
                blank.append((op.start, op.end))
        elif tok.kind == "NAME" and word in R2S:
            raise QueryParseError(f"{word} goes right after SELECT or CONSTRUCT", tok.line, tok.column)
        elif tok.kind == "NAME" and word == "FROM":
            windows_before = len(windows)
            _parse_from(cur, prefixes, windows, static_graphs, named_graphs)
            if len(windows) > windows_before:
                _check_window_name(windows, tok)
            blank.append((tok.start, cur.last.end))
        elif tok.kind == "NAME" and word == "WINDOW":
            target = cur.next("a window name")
            if target.kind not in ("IRI", "PNAME"):
                raise QueryParseError(f"expected a window name after WINDOW, found {target.text!r}",
                                      target.line, target.column)
            window_refs.append((target, _expand(target, prefixes)))
            rewrites.append((tok.start, tok.end, "GRAPH "))
        elif tok.kind == "NAME" and word == "SERVICE":
            raise QueryParseError("SERVICE (federated query) is not supported in continuous queries",
                                  tok.line, tok.column)
        elif tok.kind == "NAME" and word == "STREAM" and cur.peek() is not None \
                and cur.peek().kind in ("IRI", "PNAME"):  # type: ignore[union-attr]
            raise QueryParseError("STREAM <iri> [RANGE …] { … } inside WHERE is CQELS syntax, not supported: "
                                  "declare the window with FROM STREAM or FROM NAMED WINDOW … ON …",
                                  tok.line, tok.column)
        elif tok.kind == "NAME" and word == "ORDER" and cur.peek_word() == "BY":
            ordered = True
    if form is None or form_tok is None:
        tok = cur.tokens[body_start] if body_start < len(tokens) else tokens[-1]
        raise QueryParseError("expected SELECT, CONSTRUCT, ASK or DESCRIBE", tok.line, tok.column)
    if not windows:
        raise QueryParseError("a continuous query needs at least one FROM STREAM <iri> [RANGE …]",
                              tokens[-1].line, tokens[-1].column)
    if kind == "STREAM" and form not in ("CONSTRUCT", "DESCRIBE"):
        raise QueryParseError(f"a stream is made of triples: REGISTER STREAM needs CONSTRUCT, not {form} "
                              "(use REGISTER QUERY for SELECT and ASK)", form_tok.line, form_tok.column)
    _check_steps(windows)
    effective = report or policy
    if effective is not None and effective.trigger == "periodic" and not any(w.is_time for w in windows):
        raise QueryParseError("REPORT PERIODIC (COMPUTED EVERY) needs a time window; count windows are "
                              "evaluated at every message", name_tok.line, name_tok.column)
    names = {w.name for w in windows if w.name is not None}
    for target, iri in window_refs:
        if iri not in names:
            raise QueryParseError(f"WINDOW {target.text}: no such window (declare it with FROM NAMED WINDOW "
                                  f"{target.text} ON <stream> [RANGE …])", target.line, target.column)

    for tok in tokens[body_start:]:
        if tok.kind == "PNAME" and not tok.text.startswith("_:"):
            prefix = tok.text.split(":", 1)[0]
            if prefix not in prefixes:
                raise QueryParseError(f"unknown prefix {prefix!r} in {tok.text!r} (declare it with PREFIX)",
                                      tok.line, tok.column)
    _check_functions(tokens[body_start:], prefixes)

    all_params = params + list(extra_params or [])
    seen: set[str] = set()
    for p in all_params:
        if p.name in seen:
            raise QueryParseError(f"parameter ?{p.name} is defined twice", 1, 1)
        seen.add(p.name)
    for w in windows:
        if w.range_param is not None and w.range_param not in seen:
            raise QueryParseError(f"RANGE ?{w.range_param}: no such parameter (declare it with PARAM)",
                                  *w.range_at)
    blanked = sorted(blank)
    var_spans: dict[str, list[tuple[int, int]]] = {}
    for tok in tokens[body_start:]:
        if tok.kind == "VAR" and tok.text[1:] in seen and not _inside(tok.start, blanked):
            var_spans.setdefault(tok.text[1:], []).append((tok.start, tok.end))

    output_stream = None
    if kind == "STREAM":
        output_stream = _expand(name_tok, prefixes) if name_tok.kind == "PNAME" else name
    return ContinuousQuery(
        name=name, kind=kind, form=form, text=text, sparql=_rewrite(text, blank, rewrites), windows=windows,
        static_graphs=static_graphs, named_graphs=named_graphs, params=all_params, var_spans=var_spans,
        report=report or policy or ReportPolicy(), r2s=r2s, output_stream=output_stream, ordered=ordered,
    )


def _inside(offset: int, spans: list[tuple[int, int]]) -> bool:
    return any(s <= offset < e for s, e in spans)


def _rewrite(text: str, spans: list[tuple[int, int]], rewrites: list[tuple[int, int, str]]) -> str:
    chars = list(text)
    for start, end in spans:
        for k in range(start, end):
            if chars[k] not in "\r\n":
                chars[k] = " "
    for start, end, replacement in rewrites:
        assert len(replacement) == end - start
        chars[start:end] = list(replacement)
    return "".join(chars)


def _parse_policies(cur: _Cursor) -> ReportPolicy:
    """``policy (AND policy)*`` after REPORT; NON EMPTY combines with one trigger."""
    trigger: str | None = None
    period: int | None = None
    non_empty = False
    while True:
        tok = cur.next("a report policy (ON WINDOW CLOSE, ON CONTENT CHANGE, NON EMPTY, PERIODIC <d>)")
        word = tok.upper()
        if word == "ON":
            tok = cur.next("WINDOW CLOSE or CONTENT CHANGE")
            word = tok.upper()
        if word == "WINDOW":
            cur.expect_word("CLOSE")
            this = "window_close"
        elif word == "CONTENT":
            cur.expect_word("CHANGE")
            this = "content_change"
        elif word == "PERIODIC":
            period = _duration(cur)
            this = "periodic"
        elif word in ("NON", "NONEMPTY"):
            if word == "NON":
                cur.expect_word("EMPTY")
            if cur.peek_word() == "CONTENT":
                cur.next("CONTENT")
            non_empty = True
            this = ""
        else:
            raise QueryParseError(f"unknown report policy {tok.text!r}; use ON WINDOW CLOSE, ON CONTENT CHANGE, "
                                  "NON EMPTY or PERIODIC <duration>", tok.line, tok.column)
        if this:
            if trigger is not None:
                raise QueryParseError(f"only one of WINDOW CLOSE, CONTENT CHANGE and PERIODIC may be combined "
                                      f"(with NON EMPTY); found a second one at {tok.text!r}", tok.line, tok.column)
            trigger = this
        if cur.peek_word() != "AND":
            break
        cur.next("AND")
    return ReportPolicy(trigger or "window_close", non_empty, period)


def _parse_from(cur: _Cursor, prefixes: dict[str, str], windows: list[WindowSpec],
                static_graphs: list[str], named_graphs: list[str]) -> None:
    word = cur.peek_word()
    if word == "STREAM":
        cur.next("STREAM")
        windows.append(_parse_stream(cur, prefixes, None))
    elif word == "NAMED":
        cur.next("NAMED")
        nxt = cur.peek_word()
        if nxt == "WINDOW":
            cur.next("WINDOW")
            name_tok = cur.peek()
            name = _iri(cur, prefixes, "a window name")
            if not re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:", name):
                assert name_tok is not None
                raise QueryParseError(f"a window name must be an absolute IRI (<http://…/w> or a prefixed name), "
                                      f"not {name_tok.text}", name_tok.line, name_tok.column)
            cur.expect_word("ON")
            if cur.peek_word() == "STREAM":
                cur.next("STREAM")
            windows.append(_parse_stream(cur, prefixes, name))
        elif nxt == "STREAM":
            cur.next("STREAM")
            stream_tok = cur.peek()
            stream = _iri(cur, prefixes, "the stream IRI <…>")
            cur.i -= 1  # re-read the stream IRI as the window's stream
            assert stream_tok is not None
            windows.append(_parse_stream(cur, prefixes, stream))
        else:
            named_graphs.append(_iri(cur, prefixes, "a graph IRI"))
    else:
        static_graphs.append(_iri(cur, prefixes, "a graph IRI"))


def _check_window_name(windows: list[WindowSpec], tok: Token) -> None:
    new = windows[-1]
    if new.name is not None and sum(1 for w in windows if w.name == new.name) > 1:
        raise QueryParseError(f"window <{new.name}> is declared twice", new.line, new.column)
    if new.name is None and sum(1 for w in windows if w.name is None and w.stream == new.stream) > 1:
        raise QueryParseError(f"two FROM STREAM windows over <{new.stream}> in the default graph: name them "
                              "(FROM NAMED WINDOW <w> ON <stream> […]) and use WINDOW <w> { … }",
                              new.line, new.column)


def _check_steps(windows: list[WindowSpec]) -> None:
    first: WindowSpec | None = None
    for w in windows:
        if not w.is_time:
            continue
        if first is None:
            first = w
        elif w.step_ms != first.step_ms:
            raise QueryParseError(f"windows with different STEPs in one query are not supported (found "
                                  f"{first.step_ms} ms and {w.step_ms} ms): register one query per STEP and "
                                  "chain them with REGISTER STREAM", w.line, w.column)


def _check_functions(tokens: list[Token], prefixes: dict[str, str]) -> None:
    """Only f:timestamp of the C-SPARQL function namespace exists here; others are named."""
    for tok in tokens:
        iri = None
        if tok.kind == "IRI":
            iri = tok.text[1:-1]
        elif tok.kind == "PNAME" and ":" in tok.text and tok.text.split(":", 1)[0] in prefixes:
            prefix, local = tok.text.split(":", 1)
            iri = prefixes[prefix] + local
        if iri is not None and iri.startswith(CSPARQL_FN) and iri != CSPARQL_FN and iri not in SUPPORTED_FUNCTIONS:
            raise QueryParseError(f"the C-SPARQL function {tok.text} is not supported (only f:timestamp)",
                                  tok.line, tok.column)


def _expand(tok: Token, prefixes: dict[str, str]) -> str:
    if tok.kind == "IRI":
        return tok.text[1:-1]
    prefix, local = tok.text.split(":", 1)
    if prefix not in prefixes:
        raise QueryParseError(f"unknown prefix {prefix!r} in {tok.text!r}", tok.line, tok.column)
    return prefixes[prefix] + local


def _iri(cur: _Cursor, prefixes: dict[str, str], what: str) -> str:
    tok = cur.next(what)
    if tok.kind in ("IRI", "PNAME"):
        return _expand(tok, prefixes)
    raise QueryParseError(f"expected {what}, found {tok.text!r}", tok.line, tok.column)


def _parse_stream(cur: _Cursor, prefixes: dict[str, str], name: str | None) -> WindowSpec:
    stream_tok = cur.peek()
    stream = _iri(cur, prefixes, "the stream IRI <…>")
    assert stream_tok is not None
    where = {"line": stream_tok.line, "column": stream_tok.column}
    open_tok = cur.next("[RANGE …]")
    if open_tok.text != "[":
        raise QueryParseError(f"expected a window [RANGE …] after the stream, found {open_tok.text!r}",
                              open_tok.line, open_tok.column)
    range_tok = cur.next("RANGE")
    if range_tok.upper() in ("NOW", "ALL", "TRIPLES", "ROWS", "ITEM", "PARTITION"):
        raise QueryParseError(f"the window [{range_tok.text} …] is not supported: use [RANGE <duration> STEP "
                              "<duration>], [RANGE <duration> TUMBLING] or [RANGE TRIPLES <n>]",
                              range_tok.line, range_tok.column)
    if range_tok.upper() != "RANGE":
        raise QueryParseError(f"expected RANGE, found {range_tok.text!r}", range_tok.line, range_tok.column)
    if cur.peek_word() == "TRIPLES":
        cur.next("TRIPLES")
        num = cur.expect_kind("NUMBER", "a number of triples")
        if not num.text.isdigit() or not 0 < int(num.text) <= MAX_TRIPLES_WINDOW:
            raise QueryParseError(f"TRIPLES needs an integer between 1 and {MAX_TRIPLES_WINDOW}",
                                  num.line, num.column)
        if cur.peek_word() in ("STEP", "SLIDE", "TUMBLING"):
            extra = cur.next("]")
            raise QueryParseError(f"{extra.text} on a count window is not supported: [RANGE TRIPLES n] slides "
                                  "with every message", extra.line, extra.column)
        _close_window(cur)
        return WindowSpec(stream=stream, triples=int(num.text), name=name, **where)
    range_param = None
    range_at = (0, 0)
    if cur.peek() is not None and cur.peek().kind == "VAR":  # type: ignore[union-attr]
        var_tok = cur.next("a parameter")
        range_param, range_at = var_tok.text[1:], (var_tok.line, var_tok.column)
        range_ms = None
    else:
        range_ms = _duration(cur)
    step_tok = cur.next("STEP or TUMBLING")
    if step_tok.upper() == "SLIDE":
        raise QueryParseError("SLIDE is CQELS syntax, not supported here: write STEP", step_tok.line, step_tok.column)
    if step_tok.upper() not in ("STEP", "TUMBLING"):
        raise QueryParseError(f"expected STEP or TUMBLING, found {step_tok.text!r}", step_tok.line, step_tok.column)
    if step_tok.upper() == "TUMBLING":
        if range_ms is None:
            raise QueryParseError("a parameter RANGE needs an explicit STEP", step_tok.line, step_tok.column)
        step_ms = range_ms
    else:
        step_ms = _duration(cur)
    if range_ms is not None and range_ms <= 0:
        raise QueryParseError("RANGE must be greater than zero", range_tok.line, range_tok.column)
    if step_ms <= 0:
        raise QueryParseError("STEP must be greater than zero", step_tok.line, step_tok.column)
    if range_ms is not None and step_ms > range_ms:
        raise QueryParseError(f"STEP ({step_ms} ms) is larger than RANGE ({range_ms} ms): data between "
                              "windows would be skipped", step_tok.line, step_tok.column)
    _close_window(cur)
    return WindowSpec(stream=stream, range_ms=range_ms, step_ms=step_ms, name=name, range_param=range_param,
                      range_at=range_at, **where)


def _close_window(cur: _Cursor) -> None:
    tok = cur.next("]")
    if tok.text != "]":
        raise QueryParseError(f"expected ] to close the window, found {tok.text!r}", tok.line, tok.column)


def _duration(cur: _Cursor) -> int:
    """``3s``, ``500ms``, ``1.5m`` or ISO 8601 ``PT3S`` … as whole milliseconds."""
    num = cur.next("a duration like 3s or PT3S")
    if num.kind == "DURATION":
        try:
            return duration_ms(num.text)
        except ValueError as exc:
            raise QueryParseError(str(exc), num.line, num.column) from None
    if num.kind == "NAME" and re.fullmatch(r"P[0-9YMWDTHS.]+", num.text):
        raise QueryParseError(f"{num.text} is not a day-time duration like PT10S (years and months have no fixed "
                              "length)", num.line, num.column)
    if num.kind != "NUMBER":
        raise QueryParseError(f"expected a duration like 3s or PT3S, found {num.text!r}", num.line, num.column)
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


def duration_ms(text: str) -> int:
    """An ISO 8601 day-time duration (``PT10S``, ``PT1M30S``, ``P1D``) in whole milliseconds."""
    match = _ISO_DURATION.match(text)
    if not match or text in ("P", "PT") or text.endswith("T"):
        raise ValueError(f"{text!r} is not a day-time duration like PT10S (years and months have no fixed length)")
    days, hours, minutes, seconds = match.groups()
    total = (Decimal(days or 0) * 86_400_000 + Decimal(hours or 0) * 3_600_000 + Decimal(minutes or 0) * 60_000
             + Decimal(seconds or 0) * 1000)
    if total != total.to_integral_value():
        raise ValueError(f"{text} is not a whole number of milliseconds")
    return int(total)


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
