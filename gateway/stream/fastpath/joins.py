"""Scanning the patterns and joining them: greedy operator ordering, band joins, early filters."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from gateway.stream.fastpath.common import (
    MAX_ROWS,
    NO_TS,
    Fallback,
)
from gateway.stream.fastpath.compiler import (
    Pattern,
    Plan,
)
from gateway.stream.fastpath.values import (
    Expr,
    Frame,
    RunContext,
    _ebv,
    _take,
)

_EMPTY = np.zeros(0, dtype=np.int64)
_EMPTY_REL = (_EMPTY, _EMPTY, _EMPTY)


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
