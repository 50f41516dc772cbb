"""From rdflib's SPARQL algebra to a :class:`Plan`, or :class:`NotCompilable` with the reason."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from pyoxigraph import Literal, NamedNode

from gateway.rdf.terms import (
    XSD,
    Term,
    canonical_term,
)
from gateway.stream.evaluate import TIMESTAMP_FN
from gateway.stream.fastpath.common import (
    KIND_OTHER,
    NotCompilable,
    TermTable,
    _classify,
    _ids,
)
from gateway.stream.fastpath.values import (
    _CMP,
    Expr,
    Frame,
    RunContext,
    Val,
    _arith,
    _bool_val,
    _compare,
    _const,
    _const_val,
    _logic,
    _negate,
    _not,
    _num,
    _term_val,
    _ts_lookup,
    _ts_val,
    _unbound,
)

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
    if _is_iri(term):
        return NamedNode(str(term))
    if _is_literal(term):
        if term.language:
            return Literal(str(term), language=term.language)
        return canonical_term(Literal(str(term), datatype=NamedNode(str(term.datatype or XSD + "string"))))
    return None
