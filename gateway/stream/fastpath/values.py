"""Columns of values and frames of solutions, and SPARQL's operators on them (error semantics kept)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from pyoxigraph import NamedNode

from gateway.rdf.terms import (
    Term,
)
from gateway.stream.fastpath.common import (
    KIND_DEC,
    KIND_INT,
    KIND_IRI,
    KIND_OTHER,
    KIND_STR,
    LIMIT,
    MAX_ABS_UNITS,
    NO_TS,
    SCALE,
    Fallback,
    TermTable,
)

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
