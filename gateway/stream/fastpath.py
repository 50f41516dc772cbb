"""The fast path: a columnar (NumPy) executor for the queries it can prove it evaluates exactly.

Why: a generic SPARQL engine evaluates a window's joins solution by solution and loads a fresh
store per window (pyoxigraph ~1 s per window for the papers' query at 20 people × 30 Hz). Over
dictionary-encoded columns the same semantics take milliseconds.

What it covers (the planner reads rdflib's SPARQL algebra; anything else raises
:class:`NotCompilable` and the query uses the general path)::

    SELECT [DISTINCT] <vars | (aggregate or expression AS ?v)>
    WHERE { <basic graph pattern: constant predicates, any subjects/objects>
            BIND(<expr> AS ?v) … FILTER(<expr>) … }        # over the default graph:
    [GROUP BY ?v …] [HAVING (<expr>)]                       # stream windows + static graphs

    expr  := numbers | IRIs | strings | ?var | f:timestamp(a, <p>, b)
             | + - * | < <= > >= = != | && || ! | (…)
    aggregates: COUNT(*), COUNT([DISTINCT] expr), SUM, AVG, MIN, MAX (numbers), SAMPLE(group key)
    HAVING / SELECT expressions additionally allow / (xsd:decimal division, as pyoxigraph)

How it stays exact: terms are integers (ids) and numbers fixed-point integers (9 fractional
digits, |value| <= 10**6; timestamps exact milliseconds); SPARQL's error semantics are kept (an
IRI compared with ``<`` is an error, ``&&``/``||`` are three-valued); datatypes follow XPath
(integer op integer is integer, AVG and ``/`` give decimal, MIN/MAX keep the chosen value's
type); results are canonical XSD terms. Whatever a window holds that this cannot decide exactly —
doubles, strings compared with ``<``, a number compared with a string, overflow, an aggregate over
an error, a MIN/MAX tie between an integer and a decimal — raises :class:`Fallback` and that
window is evaluated by the general path. ``tests/stream/test_fastpath_agreement.py`` compares the
two paths term by term on random streams.
"""

from __future__ import annotations

import decimal
import itertools
from collections.abc import Callable
from dataclasses import dataclass, field
from decimal import Decimal
from typing import Any

import numpy as np
from pyoxigraph import BlankNode, Literal, NamedNode

from gateway.rdf.terms import (
    XSD,
    XSD_BOOLEAN,
    XSD_DECIMAL,
    XSD_INTEGER,
    Term,
    Triple,
    canonical_decimal,
)
from gateway.stream.evaluate import TIMESTAMP_FN, Evaluation, Row, WindowData

SCALE = 9  # fractional digits of the fixed-point numbers
MAX_ABS_UNITS = 10**15  # |value| <= 10**6 at SCALE
LIMIT = 2**62  # headroom below int64 for every intermediate
NO_TS = np.iinfo(np.int64).min
MAX_ROWS = 30_000_000  # intermediate solutions; beyond this the window goes the general way
MAX_TERMS = 2_000_000
KIND_INT, KIND_DEC, KIND_IRI, KIND_STR, KIND_OTHER = 0, 1, 2, 3, 4
_CTX = decimal.Context(prec=80, rounding=decimal.ROUND_DOWN)
_E18 = Decimal(10) ** 18
_ids = itertools.count(1)


class NotCompilable(Exception):
    """The query is outside what the fast path evaluates; the message says why."""


class Fallback(Exception):
    """This window's data is outside what the fast path decides exactly."""


# ---------------------------------------------------------------------------------------------
# Terms as integers.


class TermTable:
    """Term ⇄ id, with each id's kind and fixed-point value (for numbers; for simple strings
    ``units`` is 1 when non-empty, so the effective boolean value is ``units != 0`` for both)."""

    def __init__(self) -> None:
        self.generation = 0
        self.reset()

    def reset(self) -> None:
        self.ids: dict[Term, int] = {}
        self.terms: list[Term] = []
        self._units = np.zeros(4096, dtype=np.int64)
        self._kind = np.zeros(4096, dtype=np.int8)
        self.generation += 1

    def __len__(self) -> int:
        return len(self.terms)

    @property
    def units(self) -> np.ndarray:
        return self._units

    @property
    def kind(self) -> np.ndarray:
        return self._kind

    def id(self, term: Term) -> int:
        got = self.ids.get(term)
        if got is not None:
            return got
        n = len(self.terms)
        if n >= len(self._units):
            self._units = np.concatenate([self._units, np.zeros(n, dtype=np.int64)])
            self._kind = np.concatenate([self._kind, np.zeros(n, dtype=np.int8)])
        kind, units = _classify(term)
        self._units[n] = units
        self._kind[n] = kind
        self.ids[term] = n
        self.terms.append(term)
        return n


def _classify(term: Term) -> tuple[int, int]:
    if isinstance(term, (NamedNode, BlankNode)):
        return KIND_IRI, 0
    if term.language:
        return KIND_OTHER, 0
    datatype = term.datatype.value
    if datatype == XSD + "string":
        return KIND_STR, 1 if term.value else 0
    if datatype in (XSD + "integer", XSD + "decimal"):
        try:
            units = Decimal(term.value).scaleb(SCALE, context=_CTX)
        except decimal.InvalidOperation:
            return KIND_OTHER, 0
        if units == units.to_integral_value() and abs(units) <= MAX_ABS_UNITS:
            return (KIND_INT if datatype == XSD + "integer" else KIND_DEC), int(units)
    return KIND_OTHER, 0


# ---------------------------------------------------------------------------------------------
# Values of expressions over a frame of n solutions.


@dataclass
class Val:
    """A column of values: ``kind`` per row (KIND_*), fixed-point ``units`` at ``scale`` for
    numbers, term ``ids`` (-1: a computed value) and ``valid`` (False: unbound or an error).
    Booleans are ``kind`` -1 with ``units`` 0/1."""

    kind: np.ndarray
    units: np.ndarray
    ids: np.ndarray
    valid: np.ndarray
    scale: int = SCALE
    num_only: bool = False  # every valid row is a number (lets comparisons skip the kind checks)
    peak: int | None = None  # a bound on |units| of the valid rows (None: not known, measured when needed)

    def bound(self) -> int:
        if self.peak is None:
            self.peak = int(np.abs(self.units[self.valid]).max()) if np.any(self.valid) else 0
        return self.peak

    @property
    def n(self) -> int:
        return len(self.valid)


BOOL = -1


def _const(n: int, value: Any, dtype: Any) -> np.ndarray:
    """A read-only column holding one value (no memory per row)."""
    return np.broadcast_to(np.asarray(value, dtype=dtype), (n,))


def _pick(arr: np.ndarray, idx: np.ndarray) -> np.ndarray:
    if arr.ndim == 1 and arr.strides == (0,) and len(arr):
        return np.broadcast_to(arr[:1], (len(idx),))
    return arr[idx]


def _bool_val(value: np.ndarray, valid: np.ndarray) -> Val:
    n = len(value)
    return Val(_const(n, BOOL, np.int8), value, _const(n, -1, np.int64), valid, 0)


def _is_bool(v: Val) -> bool:
    return v.n > 0 and v.kind.strides == (0,) and int(v.kind[0]) == BOOL


class Frame:
    """Solutions, lazily. A scanned pattern holds its columns; a join holds its two sides and the
    row index of each side per solution; a filter of a join only shortens those two index arrays.
    A column is gathered (and cached) when something reads it, so a join of 1,800 × 1,800 readings
    never copies columns nobody looks at."""

    def __init__(self, n: int, cols: dict[str, np.ndarray] | None = None, ts: dict[int, np.ndarray] | None = None,
                 join: tuple[Frame, Frame, np.ndarray, np.ndarray] | None = None,
                 computed: dict[str, Val] | None = None) -> None:
        self.n = n
        self.cols = cols or {}
        self.ts = ts or {}
        self.join = join
        self.computed = computed or {}
        self._cache: dict[Any, np.ndarray] = {}
        if join is None:
            self._vars = set(self.cols)
            self._ts_keys = set(self.ts)
            # patterns with triples of the static graphs only (no timestamp) in their column
            self.nullable_ts = {k for k, c in self.ts.items() if len(c) and bool((c == NO_TS).any())}
        else:
            self._vars = join[0]._vars | join[1]._vars
            self._ts_keys = join[0]._ts_keys | join[1]._ts_keys
            self.nullable_ts = join[0].nullable_ts | join[1].nullable_ts

    def has(self, var: str) -> bool:
        return var in self._vars

    def vars(self) -> set[str]:
        return self._vars

    def col(self, var: str) -> np.ndarray:
        got = self._cache.get(var)
        if got is None:
            if self.join is None:
                got = self.cols[var]
            else:
                left, right, li, ri = self.join
                got = left.col(var)[li] if var in left._vars else right.col(var)[ri]
            self._cache[var] = got
        return got

    def ts_col(self, key: int) -> np.ndarray:
        got = self._cache.get(("ts", key))
        if got is None:
            if self.join is None:
                got = self.ts[key]
            else:
                left, right, li, ri = self.join
                got = left.ts_col(key)[li] if key in left._ts_keys else right.ts_col(key)[ri]
            self._cache[("ts", key)] = got
        return got

    def take(self, idx: np.ndarray) -> Frame:
        computed = {k: _take(v, idx) for k, v in self.computed.items()}
        if self.join is None:
            out = Frame(len(idx), {v: c[idx] for v, c in self.cols.items()}, {k: c[idx] for k, c in self.ts.items()},
                        computed=computed)
            out.nullable_ts = self.nullable_ts  # (a subset of rows: still a safe answer)
            return out
        left, right, li, ri = self.join
        return Frame(len(idx), join=(left, right, li[idx], ri[idx]), computed=computed)

    def keep(self, mask: np.ndarray) -> Frame:
        if mask.all():
            return self
        return self.take(np.flatnonzero(mask))


def _take(v: Val, idx: np.ndarray) -> Val:
    return Val(_pick(v.kind, idx), _pick(v.units, idx), _pick(v.ids, idx), _pick(v.valid, idx), v.scale, v.num_only,
               v.peak)


Expr = Callable[[Frame, "RunContext"], Val]


@dataclass
class RunContext:
    table: TermTable
    lookups: dict[str, tuple[np.ndarray, np.ndarray]]  # predicate -> (sorted s*M+o keys, ts)
    m: int  # key multiplier (table size)


# ---------------------------------------------------------------------------------------------
# The plan.


@dataclass
class Pattern:
    s: tuple[str, Any]  # ("var", name) | ("const", Term)
    p: NamedNode
    o: tuple[str, Any]
    index: int

    def vars(self) -> set[str]:
        return {x[1] for x in (self.s, self.o) if x[0] == "var"}


@dataclass
class Aggregate:
    res: str
    kind: str  # COUNT, SUM, AVG, MIN, MAX, SAMPLE
    arg: Expr | None
    arg_var: str | None
    distinct: bool


@dataclass
class Plan:
    """A compiled query (see the module docstring)."""

    patterns: list[Pattern]
    predicates: list[NamedNode]
    early: list[tuple[set[str], set[int], Expr]]  # filters on pattern variables, applied during the joins
    steps: list[tuple[str, str | None, Expr]]  # ("bind", var, expr) | ("filter", None, expr), in order
    grouped: bool
    group_by: list[str]
    aggregates: list[Aggregate]
    tail: list[tuple[str, str | None, Any]]  # group-level ("bind"|"filter", var, rdflib expression)
    project: list[str]
    distinct: bool
    needed: set[str] = field(default_factory=set)  # variables read after the joins
    ts_refs: set[int] = field(default_factory=set)  # patterns whose timestamps are read
    lookup_predicates: list[NamedNode] = field(default_factory=list)  # f:timestamp outside the patterns
    # early filters of the form f:timestamp(pattern a) <op> f:timestamp(pattern b): (index in early, op, a, b)
    bands: list[tuple[int, str, int, int]] = field(default_factory=list)
    table: TermTable = field(default_factory=TermTable)
    key: int = field(default_factory=lambda: next(_ids))
    _static: tuple[Any, ...] | None = None  # (static graph, table generation, its encoded columns)


def compile_query(sparql: str) -> Plan:
    """Compile SPARQL text (parameters already substituted) or raise :class:`NotCompilable`."""
    try:
        from rdflib.plugins.sparql import prepareQuery
        prepared = prepareQuery(sparql)
    except Exception as exc:  # rdflib cannot parse it: not for us
        raise NotCompilable(f"rdflib cannot translate the query: {exc}") from None
    return _Compiler().compile(prepared.algebra)


class _Compiler:
    def __init__(self) -> None:
        self.bgp_vars: set[str] = set()
        self.bound: dict[str, str] = {}  # BIND variable -> "val"
        self.patterns: list[Pattern] = []
        self.ts_patterns: dict[tuple[Any, ...], int] = {}
        self.ts_predicates: set[NamedNode] = set()
        self.bnodes: dict[str, str] = {}
        self.needed: set[str] = set()
        self.ts_refs: set[int] = set()
        self.bands: list[tuple[int, str, int, int]] = []

    def compile(self, algebra: Any) -> Plan:
        if algebra.name != "SelectQuery":
            raise NotCompilable(f"only SELECT queries ({algebra.name.replace('Query', '').upper()} goes the "
                                "general way)")
        node = algebra.p
        distinct = False
        if node.name == "Distinct":
            distinct, node = True, node.p
        if node.name != "Project":
            raise NotCompilable(f"{_op_name(node.name)} is not on the fast path")
        project = [str(v) for v in node.PV]
        node = node.p
        upper = []
        while node.name in ("Extend", "Filter"):
            upper.append(node)
            node = node.p
        grouped = node.name == "AggregateJoin"
        if grouped:
            aggregates_raw = node.A
            group = node.p
            if group.name != "Group":
                raise NotCompilable(f"unexpected {group.name} under the aggregates")
            group_exprs = list(group.expr or [])
            if not all(_is_var(e) for e in group_exprs):
                raise NotCompilable("GROUP BY an expression")
            group_by = [str(e) for e in group_exprs]
            node = group.p
            lower = []
            while node.name in ("Extend", "Filter"):
                lower.append(node)
                node = node.p
        else:
            aggregates_raw, group_by, lower, upper = [], [], upper, []
        triples = self._triples(node)
        for t in triples:
            self._pattern(t)
        if not self.patterns:
            raise NotCompilable("an empty graph pattern")
        for pat in self.patterns:
            self.bgp_vars |= pat.vars()
        early: list[tuple[set[str], set[int], Expr]] = []
        steps: list[tuple[str, str | None, Expr]] = []
        for n in reversed(lower):
            if n.name == "Extend":
                var = str(n.var)
                expr, refs = self._expr(n.expr)
                self.needed |= _vars_of(n.expr)
                self.ts_refs |= refs
                steps.append(("bind", var, expr))
                self.bound[var] = "val"
            else:
                for conjunct in _conjuncts(n.expr):
                    used = _vars_of(conjunct)
                    expr, refs = self._expr(conjunct)
                    if used <= self.bgp_vars and not (used & set(self.bound)):
                        band = self._band(conjunct)
                        if band is not None:
                            self.bands.append((len(early),) + band)
                        early.append((used, refs, expr))
                    else:
                        self.needed |= used
                        self.ts_refs |= refs
                        steps.append(("filter", None, expr))
        for v in group_by:
            if v not in self.bgp_vars:
                raise NotCompilable(f"GROUP BY ?{v}: only variables of the graph pattern")
        aggregates = [self._aggregate(a, group_by) for a in aggregates_raw]
        tail: list[tuple[str, str | None, Any]] = []
        known = set(group_by) | {a.res for a in aggregates}
        for n in reversed(upper):
            _check_tail(n.expr, known)
            if n.name == "Extend":
                tail.append(("bind", str(n.var), n.expr))
                known.add(str(n.var))
            else:
                tail.append(("filter", None, n.expr))
        if grouped:
            for v in project:
                if v not in known:
                    raise NotCompilable(f"?{v} is neither grouped nor aggregated")
        if distinct and (grouped or any(v not in self.bgp_vars for v in project)):
            raise NotCompilable("DISTINCT over computed values")
        predicates = sorted({p.p for p in self.patterns} | self.ts_predicates, key=lambda x: x.value)
        self.needed |= set(group_by) | (set() if grouped else set(project))
        return Plan(self.patterns, predicates, early, steps, grouped, group_by, aggregates, tail, project, distinct,
                    self.needed & self.bgp_vars, self.ts_refs,
                    sorted(self.ts_predicates, key=lambda x: x.value), self.bands)

    # -- the graph pattern -----------------------------------------------------------------
    def _triples(self, node: Any) -> list[tuple[Any, Any, Any]]:
        if node.name == "BGP":
            return list(node.triples)
        if node.name == "Join":
            return self._triples(node.p1) + self._triples(node.p2)
        raise NotCompilable(f"{_op_name(node.name)} is not on the fast path")

    def _node(self, x: Any) -> tuple[str, Any]:
        from rdflib.term import BNode

        if _is_var(x):
            return ("var", str(x))
        if isinstance(x, BNode):  # a blank node in a pattern is a variable nobody can project
            return ("var", self.bnodes.setdefault(str(x), f"_:{x}"))
        term = _to_ox(x)
        if term is None:
            raise NotCompilable(f"the pattern term {x!r}")
        return ("const", term)

    def _pattern(self, t: tuple[Any, Any, Any]) -> None:
        from rdflib.term import URIRef

        s, p, o = t
        if not isinstance(p, URIRef):
            raise NotCompilable("variable predicates and property paths are not on the fast path")
        self.patterns.append(Pattern(self._node(s), NamedNode(str(p)), self._node(o), len(self.patterns)))

    # -- expressions --------------------------------------------------------------------------
    def _expr(self, e: Any) -> tuple[Expr, set[int]]:
        """A row-level expression; also returns the patterns whose timestamps it reads."""
        refs: set[int] = set()
        return self._compile(e, refs), refs

    def _compile(self, e: Any, refs: set[int]) -> Expr:
        name = getattr(e, "name", None)
        if _is_var(e):
            var = str(e)
            if var in self.bound:
                return lambda f, ctx, v=var: f.computed[v] if v in f.computed else _unbound(f.n)
            if var in self.bgp_vars:
                return lambda f, ctx, v=var: _term_val(f.col(v), ctx)
            return lambda f, ctx: _unbound(f.n)  # never bound: an error in every row
        if _is_literal(e) or _is_iri(e):
            term = _to_ox(e)
            if term is None:
                raise NotCompilable(f"the constant {e!r}")
            if isinstance(term, Literal) and term.datatype.value == XSD + "boolean":
                value = term.value in ("true", "1")
                return lambda f, ctx: _bool_val(_const(f.n, value, bool), _const(f.n, True, bool))
            kind, _ = _classify(term)
            if kind == KIND_OTHER:
                raise NotCompilable(f"the constant {term} (only integers, decimals, strings and IRIs)")
            return lambda f, ctx, t=term: _const_val(t, f.n, ctx)
        if name == "Function":
            if str(e.iri) != TIMESTAMP_FN:
                raise NotCompilable(f"the function <{e.iri}>")
            return self._timestamp(list(e.expr or []), refs)
        if name == "RelationalExpression":
            if e.op not in _CMP:
                raise NotCompilable(f"the operator {e.op}")
            a, b = self._compile(e.expr, refs), self._compile(e.other, refs)
            return lambda f, ctx, op=e.op: _compare(op, a(f, ctx), b(f, ctx), ctx)
        if name in ("ConditionalAndExpression", "ConditionalOrExpression"):
            parts = [self._compile(e.expr, refs)] + [self._compile(x, refs) for x in e.other]
            conj = name.startswith("ConditionalAnd")
            return lambda f, ctx: _logic(conj, [p(f, ctx) for p in parts], ctx)
        if name == "UnaryNot":
            inner = self._compile(e.expr, refs)
            return lambda f, ctx: _not(inner(f, ctx), ctx)
        if name in ("UnaryMinus", "UnaryPlus"):
            inner = self._compile(e.expr, refs)
            if name == "UnaryPlus":
                return lambda f, ctx: _num(inner(f, ctx), ctx)
            return lambda f, ctx: _negate(_num(inner(f, ctx), ctx))
        if name in ("AdditiveExpression", "MultiplicativeExpression"):
            if name == "MultiplicativeExpression" and any(op != "*" for op in e.op):
                raise NotCompilable("division in a row-level expression (xsd:decimal division goes the general way)")
            first = self._compile(e.expr, refs)
            rest = [(op, self._compile(x, refs)) for op, x in zip(e.op, e.other)]

            def arith(f: Frame, ctx: RunContext) -> Val:
                acc = _num(first(f, ctx), ctx)
                for op, x in rest:
                    acc = _arith(op, acc, _num(x(f, ctx), ctx))
                return acc
            return arith
        raise NotCompilable(f"the expression {name or type(e).__name__}")

    def _timestamp(self, args: list[Any], refs: set[int]) -> Expr:
        from rdflib.term import URIRef

        if len(args) != 3 or not isinstance(args[1], URIRef):
            raise NotCompilable("f:timestamp needs (subject, <constant predicate>, object)")
        s, p, o = self._node(args[0]), NamedNode(str(args[1])), self._node(args[2])
        for pat in self.patterns:
            if pat.s == s and pat.p == p and pat.o == o:
                refs.add(pat.index)
                return lambda f, ctx, i=pat.index: _ts_val(f.ts_col(i), i in f.nullable_ts)
        for x in (s, o):
            if x[0] == "var" and x[1] not in self.bgp_vars:
                raise NotCompilable("f:timestamp of a variable outside the graph pattern")
        self.ts_predicates.add(p)
        return lambda f, ctx: _ts_lookup(f, ctx, s, p, o)

    def _band(self, e: Any) -> tuple[str, int, int] | None:
        """``f:timestamp(a) op f:timestamp(b)`` on two patterns' own timestamps (the C-SPARQL way to
        order two readings): the join of a and b can produce only the pairs that satisfy it."""
        if getattr(e, "name", None) != "RelationalExpression" or e.op not in ("<", "<=", ">", ">="):
            return None
        sides = []
        for side in (e.expr, e.other):
            if getattr(side, "name", None) != "Function" or str(side.iri) != TIMESTAMP_FN or len(side.expr or []) != 3:
                return None
            s, p, o = self._node(side.expr[0]), side.expr[1], self._node(side.expr[2])
            match = [pat.index for pat in self.patterns if pat.s == s and str(pat.p.value) == str(p) and pat.o == o]
            if not match:
                return None
            sides.append(match[0])
        if sides[0] == sides[1]:
            return None
        return (e.op, sides[0], sides[1])

    def _aggregate(self, agg: Any, group_by: list[str]) -> Aggregate:
        kind = agg.name.replace("Aggregate_", "").upper()
        res = str(agg.res)
        distinct = bool(getattr(agg, "distinct", None))
        arg = agg.vars
        if kind not in ("COUNT", "SUM", "AVG", "MIN", "MAX", "SAMPLE"):
            raise NotCompilable(f"the aggregate {kind}")
        if kind == "COUNT" and (arg == "*" or arg is None):
            if distinct:
                raise NotCompilable("COUNT(DISTINCT *)")
            return Aggregate(res, kind, None, None, False)
        if kind == "SAMPLE":
            if _is_var(arg) and str(arg) in group_by:
                return Aggregate(res, kind, None, str(arg), False)
            raise NotCompilable("SAMPLE of something else than a group key")
        if distinct and kind != "COUNT":
            raise NotCompilable(f"{kind}(DISTINCT …)")
        expr, refs = self._expr(arg)
        self.needed |= _vars_of(arg)
        self.ts_refs |= refs
        return Aggregate(res, kind, expr, str(arg) if _is_var(arg) else None, distinct)


def _op_name(name: str) -> str:
    return {"OrderBy": "ORDER BY", "Slice": "LIMIT/OFFSET", "LeftJoin": "OPTIONAL", "Union": "UNION",
            "Minus": "MINUS", "Graph": "GRAPH / WINDOW", "ToMultiSet": "a sub-query or VALUES",
            "values": "VALUES", "Reduced": "REDUCED"}.get(name, name)


def _conjuncts(e: Any) -> list[Any]:
    if getattr(e, "name", None) == "ConditionalAndExpression":
        out = []
        for part in [e.expr] + list(e.other):
            out.extend(_conjuncts(part))
        return out
    return [e]


def _vars_of(e: Any) -> set[str]:
    if _is_var(e):
        return {str(e)}
    out: set[str] = set()
    if isinstance(e, dict):
        for k, v in e.items():
            if k != "_vars":
                out |= _vars_of(v)
    elif isinstance(e, (list, tuple)):
        for v in e:
            out |= _vars_of(v)
    return out


def _check_tail(e: Any, known: set[str]) -> None:
    name = getattr(e, "name", None)
    if _is_var(e):
        if str(e) not in known:
            raise NotCompilable(f"?{e} in HAVING/SELECT is not an aggregate or a group key")
        return
    if _is_literal(e) or _is_iri(e):
        if _to_ox(e) is None:
            raise NotCompilable(f"the constant {e!r}")
        return
    if name == "RelationalExpression" and e.op in _CMP:
        _check_tail(e.expr, known)
        _check_tail(e.other, known)
        return
    if name in ("ConditionalAndExpression", "ConditionalOrExpression", "AdditiveExpression",
                "MultiplicativeExpression"):
        _check_tail(e.expr, known)
        for x in e.other:
            _check_tail(x, known)
        return
    if name in ("UnaryNot", "UnaryMinus", "UnaryPlus"):
        _check_tail(e.expr, known)
        return
    raise NotCompilable(f"the expression {name or type(e).__name__} in HAVING/SELECT")


def _is_var(x: Any) -> bool:
    from rdflib.term import Variable
    return isinstance(x, Variable)


def _is_literal(x: Any) -> bool:
    from rdflib.term import Literal as RLiteral
    return isinstance(x, RLiteral)


def _is_iri(x: Any) -> bool:
    from rdflib.term import URIRef
    return isinstance(x, URIRef)


def _to_ox(term: Any) -> Term | None:
    from gateway.rdf.terms import canonical_term

    if _is_iri(term):
        return NamedNode(str(term))
    if _is_literal(term):
        if term.language:
            return Literal(str(term), language=term.language)
        return canonical_term(Literal(str(term), datatype=NamedNode(str(term.datatype or XSD + "string"))))
    return None


# ---------------------------------------------------------------------------------------------
# Value operations (SPARQL semantics over columns).

_CMP: dict[str, Callable[[Any, Any], Any]] = {
    "<": np.less, ">": np.greater, "<=": np.less_equal, ">=": np.greater_equal, "=": np.equal, "!=": np.not_equal,
}


def _unbound(n: int) -> Val:
    return Val(_const(n, KIND_OTHER, np.int8), _const(n, 0, np.int64), _const(n, -1, np.int64),
               _const(n, False, bool), SCALE, True)


def _term_val(ids: np.ndarray, ctx: RunContext) -> Val:
    kind = ctx.table.kind[ids]
    return Val(kind, ctx.table.units[ids], ids, _const(len(ids), True, bool), SCALE,
               bool(np.all(kind <= KIND_DEC)), MAX_ABS_UNITS)


def _const_val(term: Term, n: int, ctx: RunContext) -> Val:
    tid = ctx.table.id(term)
    kind = int(ctx.table.kind[tid])
    units = int(ctx.table.units[tid])
    return Val(_const(n, kind, np.int8), _const(n, units, np.int64), _const(n, tid, np.int64),
               _const(n, True, bool), SCALE, kind <= KIND_DEC, abs(units))


def _ts_val(ts: np.ndarray, nullable: bool = True) -> Val:
    """Timestamps (exact ms, xsd:integer); NO_TS (a static-only triple) is unbound."""
    n = len(ts)
    if not nullable:
        return Val(_const(n, KIND_INT, np.int8), ts, _const(n, -1, np.int64), _const(n, True, bool), 0, True)

    valid = ts != NO_TS
    return Val(_const(n, KIND_INT, np.int8), np.where(valid, ts, 0), _const(n, -1, np.int64), valid, 0, True)


def _ts_lookup(f: Frame, ctx: RunContext, s: tuple[str, Any], p: NamedNode, o: tuple[str, Any]) -> Val:
    keys, stamps = ctx.lookups.get(p.value, (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)))

    def column(x: tuple[str, Any]) -> np.ndarray:
        if x[0] == "var":
            return f.col(x[1])
        return np.full(f.n, ctx.table.ids.get(x[1], -1), dtype=np.int64)

    cs, co = column(s), column(o)
    want = np.where((cs >= 0) & (co >= 0) & (cs < ctx.m) & (co < ctx.m), cs * ctx.m + co, -1)
    pos = np.searchsorted(keys, want)
    pos_c = np.minimum(pos, max(len(keys) - 1, 0))
    found = (pos < len(keys)) & (keys[pos_c] == want) if len(keys) else np.zeros(f.n, dtype=bool)
    ts = np.where(found, stamps[pos_c] if len(keys) else 0, NO_TS)
    return _ts_val(ts)


def _num(v: Val, ctx: RunContext) -> Val:
    """``v`` in a numeric context: IRIs, strings and booleans are type errors (invalid); other
    literals (doubles, dates …) cannot be decided exactly here."""
    if v.num_only:
        return v
    numeric = v.kind <= KIND_DEC
    numeric &= v.kind >= 0
    if np.any(v.valid & (v.kind == KIND_OTHER)):
        raise Fallback("a value that is not an exact integer/decimal in arithmetic or comparison")
    return Val(v.kind, v.units, v.ids, v.valid & numeric, v.scale, True)


def _negate(v: Val) -> Val:
    return Val(v.kind, -v.units, _const(v.n, -1, np.int64), v.valid, v.scale, True, v.peak)


def _align(a: Val, b: Val) -> tuple[np.ndarray, np.ndarray, int]:
    scale = max(a.scale, b.scale)
    return _rescale(a, scale), _rescale(b, scale), scale


def _rescale(v: Val, scale: int) -> np.ndarray:
    if v.scale == scale:
        return v.units
    factor = 10 ** (scale - v.scale)
    if v.bound() * factor > LIMIT:
        raise Fallback("numbers too large for exact fixed-point comparison")
    return v.units * factor


def _arith(op: str, a: Val, b: Val) -> Val:
    valid = _and(a.valid, b.valid)
    kind = _result_kind(a.kind, b.kind)
    ids = _const(a.n, -1, np.int64)
    if op == "*":
        a, b = _shrink(a, valid), _shrink(b, valid)
        peak = a.bound() * b.bound()
        if peak > LIMIT:
            raise Fallback("product too large for exact fixed-point arithmetic")
        units = np.where(valid, a.units * b.units, 0)
        return Val(kind, units, ids, valid, a.scale + b.scale, True, peak)
    scale = max(a.scale, b.scale)
    peak = a.bound() * 10 ** (scale - a.scale) + b.bound() * 10 ** (scale - b.scale)
    if peak > LIMIT:
        raise Fallback("sum too large for exact fixed-point arithmetic")
    ua, ub = _rescale(a, scale), _rescale(b, scale)
    units = ua + ub if op == "+" else ua - ub
    if not _all_true(valid):
        units = np.where(valid, units, 0)
    return Val(kind, units, ids, valid, scale, True, peak)


def _all_true(mask: np.ndarray) -> bool:
    return mask.ndim == 1 and mask.strides == (0,) and (len(mask) == 0 or bool(mask[0]))


def _and(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a & b`` without a pass when one side is a constant True column."""
    if _all_true(a):
        return b
    if _all_true(b):
        return a
    return a & b


def _result_kind(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """integer op integer is integer, anything else decimal (one pass at most)."""
    n = len(a)
    if a.strides == (0,) and b.strides == (0,) and n:
        return _const(n, KIND_INT if int(a[0]) == KIND_INT and int(b[0]) == KIND_INT else KIND_DEC, np.int8)
    if a.strides == (0,) and n and int(a[0]) != KIND_INT or b.strides == (0,) and n and int(b[0]) != KIND_INT:
        return _const(n, KIND_DEC, np.int8)
    return np.where((a == KIND_INT) & (b == KIND_INT), KIND_INT, KIND_DEC).astype(np.int8)


def _shrink(v: Val, valid: np.ndarray) -> Val:
    """The same numbers at the smallest scale that holds them exactly (2.000000000 → 2, scale 0)."""
    units = v.units[valid]
    scale = v.scale
    while scale > 0 and (len(units) == 0 or not np.any(units % 10)):
        units = units // 10
        scale -= 1
    if scale == v.scale:
        return v
    factor = 10 ** (v.scale - scale)
    return Val(v.kind, np.where(valid, v.units // factor, 0), v.ids, v.valid, scale, v.num_only,
               None if v.peak is None else v.peak // factor)


def _compare(op: str, a: Val, b: Val, ctx: RunContext) -> Val:
    valid = _and(a.valid, b.valid)
    if a.num_only and b.num_only:  # the common case: numbers on both sides
        ua, ub, _ = _align(a, b)
        return _bool_val(_CMP[op](ua, ub), valid)
    num = (a.kind >= 0) & (a.kind <= KIND_DEC) & (b.kind >= 0) & (b.kind <= KIND_DEC)
    iri = (a.kind == KIND_IRI) | (b.kind == KIND_IRI)
    strs = (a.kind == KIND_STR) & (b.kind == KIND_STR)
    bools = (a.kind == BOOL) & (b.kind == BOOL)
    undecided = valid & ~(num | iri | strs | bools)
    if np.any(undecided):
        raise Fallback("a comparison of values of different kinds (e.g. a number and a string)")
    result = np.zeros(a.n, dtype=bool)
    if np.any(valid & num):
        ua, ub, _ = _align(Val(a.kind, np.where(num, a.units, 0), a.ids, a.valid & num, a.scale),
                           Val(b.kind, np.where(num, b.units, 0), b.ids, b.valid & num, b.scale))
        result = np.where(num, _CMP[op](ua, ub), result)
    if op in ("=", "!="):
        same = np.where(bools, a.units == b.units, (a.ids == b.ids) & (a.ids >= 0))
        other = same if op == "=" else ~same
        result = np.where(num, result, other)
    else:
        if np.any(valid & (strs | bools)):
            raise Fallback("ordering strings or booleans")
        valid = valid & ~iri  # an IRI has no order: a type error
    return _bool_val(result, valid)


def _ebv(v: Val, ctx: RunContext) -> tuple[np.ndarray, np.ndarray]:
    """The effective boolean value: booleans, numbers (non-zero), simple strings (non-empty)."""
    if v.num_only or _is_bool(v):
        return v.valid & (v.units != 0), v.valid
    if np.any(v.valid & (v.kind == KIND_OTHER)):
        raise Fallback("the boolean value of a literal that is not a number or a simple string")
    ok = v.valid & (v.kind != KIND_IRI)
    return ok & (v.units != 0), ok


def _logic(conj: bool, parts: list[Val], ctx: RunContext) -> Val:
    n = parts[0].n
    any_true = np.zeros(n, dtype=bool)
    any_false = np.zeros(n, dtype=bool)
    all_valid = np.ones(n, dtype=bool)
    for part in parts:
        value, valid = _ebv(part, ctx)
        any_true |= valid & value
        any_false |= valid & ~value
        all_valid &= valid
    if conj:  # false wins over an error; true needs every part true
        return _bool_val(~any_false & all_valid, any_false | all_valid)
    return _bool_val(any_true, any_true | all_valid)


def _not(v: Val, ctx: RunContext) -> Val:
    value, valid = _ebv(v, ctx)
    return _bool_val(~value, valid)


# ---------------------------------------------------------------------------------------------
# Running a plan on a window.


def run_plan(plan: Plan, window: WindowData) -> Evaluation:
    """Evaluate ``plan`` on ``window``; raises :class:`Fallback` when the data needs the general path."""
    table = plan.table
    if len(table) > MAX_TERMS:
        table.reset()
        plan._static = None
    relations = _relations(plan, window)
    ctx = RunContext(table, {}, max(len(table), 1))
    for p in plan.lookup_predicates:  # f:timestamp of triples outside the pattern's own columns
        s, o, ts = relations.get(p.value, _EMPTY_REL)
        keys = s * ctx.m + o
        order = np.argsort(keys, kind="stable")
        ctx.lookups[p.value] = (keys[order], ts[order])
    frame = _join_all(plan, relations, ctx)
    for kind, var, expr in plan.steps:
        value = expr(frame, ctx)
        if kind == "bind":
            frame.computed[var] = value  # type: ignore[index]
        else:
            keep, valid = _ebv(value, ctx)
            frame = frame.keep(keep & valid)
    if plan.grouped:
        rows = _grouped_rows(plan, frame, ctx)
    else:
        rows = _plain_rows(plan, frame, ctx)
    return Evaluation(list(plan.project), rows, path="fast")


_EMPTY = np.zeros(0, dtype=np.int64)
_EMPTY_REL = (_EMPTY, _EMPTY, _EMPTY)


def _relations(plan: Plan, window: WindowData) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Per predicate (s ids, o ids, latest timestamp; NO_TS for static-only triples)."""
    table = plan.table
    wanted = {p: i for i, p in enumerate(plan.predicates)}
    parts: list[list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = [[] for _ in plan.predicates]
    if plan._static is None or plan._static[0] is not window.static or plan._static[1] != table.generation:
        plan._static = (window.static, table.generation,
                        _encode(((t, NO_TS) for t in window.static), wanted, table))
    for i, rel in enumerate(plan._static[2]):
        parts[i].append(rel)
    if window.segments is not None:
        cache_key = (plan.key, table.generation)
        for seg in window.segments:
            encoded = seg.cache.get(cache_key) if seg.sealed else None
            if encoded is None:
                encoded = _encode(seg.stamped.items(), wanted, table)
                if seg.sealed:
                    seg.cache[cache_key] = encoded
            for i, rel in enumerate(encoded):
                parts[i].append(rel)
    else:
        for i, rel in enumerate(_encode(window.stamped.items(), wanted, table)):
            parts[i].append(rel)
    out = {}
    m = max(len(table), 1)
    for p, i in wanted.items():
        pieces = [x for x in parts[i] if len(x[0])]
        if not pieces:
            out[p.value] = _EMPTY_REL
            continue
        if len(pieces) == 1:
            out[p.value] = pieces[0]
            continue
        s = np.concatenate([x[0] for x in pieces])
        o = np.concatenate([x[1] for x in pieces])
        ts = np.concatenate([x[2] for x in pieces])
        # a triple in several pieces counts once, with its latest timestamp (static first, then time order)
        key = (s * m + o)[::-1]
        _, first = np.unique(key, return_index=True)
        keep = np.sort(len(key) - 1 - first)
        out[p.value] = (s[keep], o[keep], ts[keep])
    return out


def _encode(items: Any, wanted: dict[NamedNode, int], table: TermTable) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    cols: list[tuple[list[int], list[int], list[int]]] = [([], [], []) for _ in wanted]
    known = table.ids
    add = table.id
    for (s, p, o), ts in items:
        i = wanted.get(p)
        if i is None:
            continue
        c = cols[i]
        sid = known.get(s)
        oid = known.get(o)
        c[0].append(add(s) if sid is None else sid)
        c[1].append(add(o) if oid is None else oid)
        c[2].append(ts)
    return [(np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64), np.asarray(t, dtype=np.int64))
            for a, b, t in cols]


def _scan(pat: Pattern, relations: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]], ctx: RunContext) -> Frame:
    s, o, ts = relations.get(pat.p.value, _EMPTY_REL)
    mask = np.ones(len(s), dtype=bool)
    for side, col in ((pat.s, s), (pat.o, o)):
        if side[0] == "const":
            tid = ctx.table.ids.get(side[1])
            mask &= (col == tid) if tid is not None else False
    if pat.s[0] == "var" and pat.o[0] == "var" and pat.s[1] == pat.o[1]:
        mask &= s == o
    idx = np.flatnonzero(mask)
    cols: dict[str, np.ndarray] = {}
    if pat.s[0] == "var":
        cols[pat.s[1]] = s[idx]
    if pat.o[0] == "var":
        cols[pat.o[1]] = o[idx]
    return Frame(len(idx), cols, {pat.index: ts[idx]})


@dataclass
class _Part:
    """A joined piece of the pattern: its solutions and which patterns it covers."""

    frame: Frame
    patterns: set[int]


def _join_all(plan: Plan, relations: dict[str, Any], ctx: RunContext) -> Frame:
    """Greedy operator ordering: repeatedly join the two connected pieces with the fewest results
    (counted exactly), so independent branches (e.g. two readings of a person) are joined before
    they meet; filters run as soon as their variables are there; unneeded columns are dropped."""
    parts = [_Part(_scan(p, relations, ctx), {p.index}) for p in plan.patterns]
    early = list(plan.early)
    bands = {id(plan.early[k]): (op, a, b) for k, op, a, b in plan.bands}
    for part in parts:
        early = _settle(plan, part, parts, early, ctx)
    while len(parts) > 1:
        best: tuple[int, int, int, list[str], Any] | None = None
        for i in range(len(parts)):
            for j in range(i + 1, len(parts)):
                shared = sorted(parts[i].frame.vars() & parts[j].frame.vars())
                if not shared:
                    continue
                band = _band_for(bands, early, parts[i], parts[j]) if len(shared) == 1 else None
                if band is not None:
                    total, prepared = _band_counts(parts[i].frame, parts[j].frame, shared[0], band[1], ctx)
                    prepared = (prepared, band[0])
                else:
                    total, prepared = _join_counts(parts[i].frame, parts[j].frame, shared, ctx)
                if best is None or total < best[0]:
                    best = (total, i, j, shared, prepared)
        if best is None:  # nothing connected: the two smallest, every pair
            i, j = sorted(sorted(range(len(parts)), key=lambda k: parts[k].frame.n)[:2])
            best = (parts[i].frame.n * parts[j].frame.n, i, j, [], None)
        total, i, j, shared, prepared = best
        if total > MAX_ROWS:
            raise Fallback(f"more than {MAX_ROWS} intermediate solutions")
        if isinstance(prepared, tuple) and len(prepared) == 2 and isinstance(prepared[1], tuple):
            prepared, done = prepared
            early = [e for e in early if e is not done]  # the band join applied this filter
        merged = _Part(_join(parts[i].frame, parts[j].frame, prepared, shared), parts[i].patterns | parts[j].patterns)
        parts = [p for k, p in enumerate(parts) if k not in (i, j)] + [merged]
        early = _settle(plan, merged, parts, early, ctx)
    frame = parts[0].frame
    for _, _, expr in early:  # whatever could not run earlier
        keep, valid = _ebv(expr(frame, ctx), ctx)
        frame = frame.keep(keep & valid)
    return frame


def _band_for(bands: dict[int, tuple[str, int, int]], early: list[Any], left: _Part,
              right: _Part) -> tuple[Any, tuple[str, int, int]] | None:
    """A pending ``f:timestamp(a) op f:timestamp(b)`` filter with a on one side and b on the other."""
    for entry in early:
        band = bands.get(id(entry))
        if band is None:
            continue
        op, a, b = band
        if a in left.patterns and b in right.patterns:
            return entry, (op, a, b)
        if b in left.patterns and a in right.patterns:
            return entry, ({"<": ">", ">": "<", "<=": ">=", ">=": "<="}[op], b, a)
    return None


def _band_counts(left: Frame, right: Frame, var: str, band: tuple[str, int, int], ctx: RunContext) -> tuple[int, Any]:
    """An equi-join on ``var`` that keeps only the pairs with ``ts_left op ts_right``: the right side
    is sorted by (key, rank of its timestamp), so each left row's partners are one contiguous range."""
    op, a, b = band
    lk, rk = left.col(var), right.col(var)
    x, y = left.ts_col(a), right.ts_col(b)
    l_ok = x != NO_TS if a in left.nullable_ts else None
    r_rows = np.flatnonzero(y != NO_TS) if b in right.nullable_ts else np.arange(right.n)
    values = np.unique(y[r_rows])
    width = len(values) + 1
    composite = rk[r_rows] * width + np.searchsorted(values, y[r_rows])
    order_local = np.argsort(composite, kind="stable")
    comp_sorted = composite[order_local]
    order = r_rows[order_local]
    base = lk * width
    below = np.searchsorted(values, x, "left")   # how many right timestamps are < x
    upto = np.searchsorted(values, x, "right")   # … are <= x
    if op == ">":     # y < x
        lo_key, hi_key = base, base + below
    elif op == ">=":  # y <= x
        lo_key, hi_key = base, base + upto
    elif op == "<":   # y > x
        lo_key, hi_key = base + upto, base + width
    else:             # y >= x
        lo_key, hi_key = base + below, base + width
    lo = np.searchsorted(comp_sorted, lo_key, "left")
    hi = np.searchsorted(comp_sorted, hi_key, "left")
    counts = np.maximum(hi - lo, 0)
    if l_ok is not None:
        counts = np.where(l_ok, counts, 0)
    return int(counts.sum()), (order, lo, counts)


def _settle(plan: Plan, part: _Part, parts: list[_Part], early: list[tuple[set[str], set[int], Expr]],
            ctx: RunContext) -> list[tuple[set[str], set[int], Expr]]:
    """Run the filters ``part`` can run, then drop the columns nobody will read."""
    rest = []
    for entry in early:
        used, refs, expr = entry
        if used <= part.frame.vars() and refs <= part.patterns:
            keep, valid = _ebv(expr(part.frame, ctx), ctx)
            part.frame = part.frame.keep(keep & valid)
        else:
            rest.append(entry)
    keep_vars = set(plan.needed)
    keep_ts = set(plan.ts_refs)
    for used, refs, _ in rest:
        keep_vars |= used
        keep_ts |= refs
    for other in parts:
        if other is not part:
            keep_vars |= other.frame.vars()
    del keep_vars, keep_ts  # (frames are lazy: an unread column costs nothing)
    return rest


def _join_counts(left: Frame, right: Frame, shared: list[str], ctx: RunContext) -> tuple[int, Any]:
    m = ctx.m
    lk = left.col(shared[0])
    rk = right.col(shared[0])
    if len(shared) >= 2:  # two variables in one key; any others are checked after the join
        lk = lk * m + left.col(shared[1])
        rk = rk * m + right.col(shared[1])
    order = np.argsort(rk, kind="stable")
    rks = rk[order]
    lo = np.searchsorted(rks, lk, "left")
    hi = np.searchsorted(rks, lk, "right")
    counts = hi - lo
    return int(counts.sum()), (order, lo, counts)


def _join(left: Frame, right: Frame, prepared: Any, shared: list[str]) -> Frame:
    if prepared is None:  # no shared variable: every pair
        li = np.repeat(np.arange(left.n), right.n)
        ri = np.tile(np.arange(right.n), left.n)
    else:
        order, lo, counts = prepared
        total = int(counts.sum())
        li = np.repeat(np.arange(left.n), counts)
        starts = np.repeat(lo - (np.cumsum(counts) - counts), counts)
        ri = order[starts + np.arange(total)]
    if len(shared) > 2:
        same = np.ones(len(li), dtype=bool)
        for v in shared[2:]:
            same &= left.col(v)[li] == right.col(v)[ri]
        li, ri = li[same], ri[same]
    computed = {k: _take(v, li) for k, v in left.computed.items()}
    computed.update({k: _take(v, ri) for k, v in right.computed.items()})
    return Frame(len(li), join=(left, right, li, ri), computed=computed)


# -- results without aggregates ---------------------------------------------------------------


def _plain_rows(plan: Plan, frame: Frame, ctx: RunContext) -> list[Row]:
    terms = ctx.table.terms
    if plan.distinct and frame.n:
        stacked = np.stack([frame.col(v) for v in plan.project if frame.has(v)], axis=1) \
            if any(frame.has(v) for v in plan.project) else np.zeros((frame.n, 0), dtype=np.int64)
        if stacked.shape[1]:
            _, first = np.unique(stacked, axis=0, return_index=True)
            frame = frame.take(np.sort(first))
        else:
            frame = frame.take(np.arange(1))
    columns: list[tuple[str, Any]] = []
    for v in plan.project:
        if frame.has(v):
            columns.append((v, [terms[i] for i in frame.col(v).tolist()]))
        elif v in frame.computed:
            columns.append((v, _val_terms(frame.computed[v])))
    rows: list[Row] = [{} for _ in range(frame.n)]
    for v, values in columns:
        for row, term in zip(rows, values):
            if term is not None:
                row[v] = term
    return rows


def _val_terms(v: Val) -> list[Term | None]:
    out: list[Term | None] = []
    for kind, units, valid in zip(v.kind.tolist(), v.units.tolist(), v.valid.tolist()):
        if not valid:
            out.append(None)
        elif kind == BOOL:
            out.append(Literal("true" if units else "false", datatype=XSD_BOOLEAN))
        else:
            out.append(_number_term(kind == KIND_INT, Decimal(units).scaleb(-v.scale, context=_CTX)))
    return out


def _number_term(is_int: bool, value: Decimal) -> Literal:
    if is_int:
        return Literal(str(int(value)), datatype=XSD_INTEGER)
    return Literal(canonical_decimal(value), datatype=XSD_DECIMAL)


# -- aggregates ----------------------------------------------------------------------------------


def _grouped_rows(plan: Plan, frame: Frame, ctx: RunContext) -> list[Row]:
    n = frame.n
    m = max(ctx.m, 1)
    if plan.group_by:
        if n == 0:
            return []
        if len(plan.group_by) <= 2:
            key = frame.col(plan.group_by[0])
            if len(plan.group_by) == 2:
                key = key * m + frame.col(plan.group_by[1])
            order = np.argsort(key, kind="stable")
            sorted_key = key[order]
            first = np.ones(n, dtype=bool)
            first[1:] = sorted_key[1:] != sorted_key[:-1]
            starts = np.flatnonzero(first)
            sizes = np.diff(np.append(starts, n))
            group_ids = np.cumsum(first) - 1
            heads = order[starts]
            uniq = np.stack([frame.col(v)[heads] for v in plan.group_by], axis=1)
        else:
            keys = np.stack([frame.col(v) for v in plan.group_by], axis=1)
            uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
            inverse = inverse.reshape(-1)
            order = np.argsort(inverse, kind="stable")
            sizes = np.bincount(inverse, minlength=len(uniq))
            starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
            group_ids = inverse[order]
        n_groups = len(uniq)
    else:  # one implicit group, even over no solutions
        uniq = np.zeros((1, 0), dtype=np.int64)
        order = np.arange(n)
        sizes = np.array([n], dtype=np.int64)
        starts = np.zeros(1, dtype=np.int64)
        group_ids = np.zeros(n, dtype=np.int64)
        n_groups = 1
    results: dict[str, list[Any]] = {}
    for agg in plan.aggregates:
        results[agg.res] = _aggregate(agg, frame, order, group_ids, sizes, starts, n_groups, ctx)
    rows: list[Row] = []
    terms = ctx.table.terms
    for g in range(n_groups):
        env: dict[str, Any] = {v: terms[int(uniq[g, k])] for k, v in enumerate(plan.group_by)}
        for res, values in results.items():
            env[res] = values[g]
        if not _tail(plan, env):
            continue
        row: Row = {}
        for v in plan.project:
            term = _env_term(env.get(v))
            if term is not None:
                row[v] = term
        rows.append(row)
    return rows


def _reduce(fn: Any, values: np.ndarray, starts: np.ndarray, sizes: np.ndarray, empty: Any) -> np.ndarray:
    """``fn.reduceat`` per group; groups of size 0 get ``empty``."""
    out = np.full(len(sizes), empty, dtype=values.dtype)
    nonempty = sizes > 0
    if len(values) and np.any(nonempty):
        out[nonempty] = fn.reduceat(values, starts[nonempty])
    return out


def _aggregate(agg: Aggregate, frame: Frame, order: np.ndarray, group_ids: np.ndarray, sizes: np.ndarray,
               starts: np.ndarray, n_groups: int, ctx: RunContext) -> list[Any]:
    """One aggregate per group; ``order`` sorts the frame's rows by group."""
    if agg.kind == "COUNT" and agg.arg is None:
        return [("int", Decimal(int(c))) for c in sizes]
    if agg.kind == "SAMPLE":
        return [None] * n_groups  # filled from the group key below (SAMPLE(?key) is the key)
    value = agg.arg(frame, ctx)  # type: ignore[misc]
    if agg.kind == "COUNT":
        value = _take(value, order)
        valid = value.valid
        if agg.distinct:
            return _count_distinct(value, group_ids, n_groups)
        counts = np.bincount(group_ids[valid], minlength=n_groups)
        return [("int", Decimal(int(c))) for c in counts]
    num = _num(value, ctx)
    if not _all_true(num.valid) and not np.all(num.valid):
        raise Fallback(f"{agg.kind} over a value that is unbound, an error or not a number")
    num = Val(_pick(num.kind, order), num.units[order], num.ids, num.valid, num.scale, True, num.peak)
    is_int = (num.kind == KIND_INT)
    scale = num.scale
    if agg.kind in ("SUM", "AVG"):
        largest = int(sizes.max()) if len(sizes) else 0
        peak = num.bound() if frame.n else 0
        if peak * largest > LIMIT and frame.n:  # the static bound is too loose: measure
            peak = int(np.abs(num.units).max())
        if peak * largest > LIMIT:
            raise Fallback("sum too large for exact int64 arithmetic")
        sums = _reduce(np.add, num.units, starts, sizes, 0)
        all_int = _reduce(np.logical_and, is_int, starts, sizes, True)
        out: list[Any] = []
        for g in range(n_groups):
            total = Decimal(int(sums[g])).scaleb(-scale, context=_CTX)
            if sizes[g] == 0:
                out.append(("int", Decimal(0)))
            elif agg.kind == "SUM":
                out.append(("int" if all_int[g] else "dec", total))
            else:
                out.append(("dec", _div18(total, Decimal(int(sizes[g])))))
        return out
    fn = np.minimum if agg.kind == "MIN" else np.maximum
    extreme = _reduce(fn, num.units, starts, sizes, 0)
    at = num.units == np.repeat(extreme, sizes)
    int_at = _reduce(np.logical_or, at & is_int, starts, sizes, False)
    dec_at = _reduce(np.logical_or, at & ~is_int, starts, sizes, False)
    if np.any(int_at & dec_at):
        raise Fallback(f"{agg.kind} tie between an integer and a decimal")
    return [None if sizes[g] == 0 else ("int" if int_at[g] else "dec",
                                        Decimal(int(extreme[g])).scaleb(-scale, context=_CTX))
            for g in range(n_groups)]


def _count_distinct(value: Val, group_ids: np.ndarray, n_groups: int) -> list[Any]:
    valid = value.valid
    if np.any(valid & (value.ids < 0)):
        # computed values: distinct as (value, type) pairs at one scale
        ident = np.stack([value.units, value.kind.astype(np.int64)], axis=1)
    else:
        ident = value.ids[:, None]
    pairs = np.concatenate([group_ids[:, None], ident], axis=1)[valid]
    uniq = np.unique(pairs, axis=0) if len(pairs) else pairs
    counts = np.bincount(uniq[:, 0], minlength=n_groups) if len(uniq) else np.zeros(n_groups, dtype=np.int64)
    return [("int", Decimal(int(c))) for c in counts]


def _div18(a: Decimal, b: Decimal) -> Decimal:
    """pyoxigraph's xsd:decimal division: 18 fractional digits, truncated toward zero."""
    return _CTX.divide_int(_CTX.multiply(a, _E18), b).scaleb(-18, context=_CTX)


def _tail(plan: Plan, env: dict[str, Any]) -> bool:
    for agg in plan.aggregates:
        if agg.kind == "SAMPLE":
            env[agg.res] = env.get(agg.arg_var or "")
    for kind, var, node in plan.tail:
        value = _group_expr(node, env)
        if kind == "filter":
            if _group_ebv(value) is not True:
                return False
        else:
            env[var] = value  # type: ignore[index]
    return True


def _group_ebv(value: Any) -> bool | None:
    if isinstance(value, bool):
        return value
    if isinstance(value, tuple):
        return value[1] != 0
    if value is None:
        return None
    raise Fallback("the boolean value of a term in HAVING")


def _group_expr(e: Any, env: dict[str, Any]) -> Any:
    """SPARQL on one group's values; numbers are ("int"|"dec", Decimal), errors None."""
    name = getattr(e, "name", None)
    if _is_var(e):
        return env.get(str(e))
    if _is_literal(e) or _is_iri(e):
        term = _to_ox(e)
        if isinstance(term, Literal) and term.datatype.value in (XSD + "integer", XSD + "decimal"):
            return ("int" if term.datatype.value == XSD + "integer" else "dec", Decimal(term.value))
        if isinstance(term, Literal) and term.datatype.value == XSD + "boolean":
            return term.value == "true"
        return term
    if name == "RelationalExpression":
        return _group_compare(e.op, _group_expr(e.expr, env), _group_expr(e.other, env))
    if name in ("ConditionalAndExpression", "ConditionalOrExpression"):
        vals = [_group_ebv(_group_expr(x, env)) for x in [e.expr] + list(e.other)]
        if name == "ConditionalAndExpression":
            if any(v is False for v in vals):
                return False
            return True if all(v is True for v in vals) else None
        if any(v is True for v in vals):
            return True
        return False if all(v is False for v in vals) else None
    if name == "UnaryNot":
        v = _group_ebv(_group_expr(e.expr, env))
        return None if v is None else not v
    if name in ("UnaryMinus", "UnaryPlus"):
        v = _group_num(_group_expr(e.expr, env))
        return None if v is None else (v[0], -v[1] if name == "UnaryMinus" else v[1])
    if name in ("AdditiveExpression", "MultiplicativeExpression"):
        acc = _group_num(_group_expr(e.expr, env))
        for op, other in zip(e.op, e.other):
            b = _group_num(_group_expr(other, env))
            if acc is None or b is None:
                return None
            kind = "int" if acc[0] == b[0] == "int" else "dec"
            if op == "+":
                acc = (kind, _CTX.add(acc[1], b[1]))
            elif op == "-":
                acc = (kind, _CTX.subtract(acc[1], b[1]))
            elif op == "*":
                product = _CTX.multiply(acc[1], b[1])
                if kind == "dec":
                    product = product.quantize(Decimal(1).scaleb(-18), rounding=decimal.ROUND_DOWN, context=_CTX)
                acc = (kind, product)
            else:
                if b[1] == 0:
                    return None
                acc = ("dec", _div18(acc[1], b[1]))
        return acc
    raise Fallback(f"the expression {name} in HAVING/SELECT")


def _group_num(v: Any) -> tuple[str, Decimal] | None:
    if isinstance(v, tuple):
        return v
    if v is None or isinstance(v, (NamedNode, BlankNode)) or isinstance(v, bool):
        return None  # a type error
    raise Fallback("arithmetic on a literal that is not an exact number")


def _group_compare(op: str, a: Any, b: Any) -> Any:
    if a is None or b is None:
        return None
    if isinstance(a, tuple) and isinstance(b, tuple):
        return bool(_CMP[op](a[1], b[1]))
    if isinstance(a, (NamedNode, BlankNode)) or isinstance(b, (NamedNode, BlankNode)):
        if op == "=":
            return a == b
        if op == "!=":
            return a != b
        return None
    if isinstance(a, bool) and isinstance(b, bool) and op in ("=", "!="):
        return (a == b) == (op == "=")
    if isinstance(a, Literal) and isinstance(b, Literal) and a.datatype == b.datatype == NamedNode(XSD + "string") \
            and op in ("=", "!="):
        return (a == b) == (op == "=")
    raise Fallback("a comparison in HAVING the fast path cannot decide exactly")


def _env_term(value: Any) -> Term | None:
    if value is None:
        return None
    if isinstance(value, tuple):
        return _number_term(value[0] == "int", value[1])
    if isinstance(value, bool):
        return Literal("true" if value else "false", datatype=XSD_BOOLEAN)
    return value


__all__ = ["Fallback", "NotCompilable", "Plan", "TermTable", "compile_query", "run_plan", "Triple"]
