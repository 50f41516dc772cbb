"""Solutions to result rows: projection, DISTINCT, GROUP BY aggregates, HAVING and SELECT expressions."""

from __future__ import annotations

import decimal
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
    canonical_decimal,
)
from gateway.stream.evaluate import Row
from gateway.stream.fastpath.common import (
    _CTX,
    _E18,
    KIND_INT,
    LIMIT,
    Fallback,
)
from gateway.stream.fastpath.compiler import (
    Aggregate,
    Plan,
    _is_iri,
    _is_literal,
    _is_var,
    _to_ox,
)
from gateway.stream.fastpath.values import (
    _CMP,
    BOOL,
    Frame,
    RunContext,
    Val,
    _all_true,
    _num,
    _pick,
    _take,
)


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
