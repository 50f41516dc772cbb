"""Running a plan on a window: encoding the window's triples (cached per sealed pane), joins, rows."""

from __future__ import annotations

from typing import Any

import numpy as np
from pyoxigraph import NamedNode

from gateway.stream.evaluate import Evaluation, WindowData
from gateway.stream.fastpath.common import (
    NO_TS,
    TERMS_FLOOR,
    TERMS_SLACK,
    TermTable,
)
from gateway.stream.fastpath.compiler import (
    Plan,
)
from gateway.stream.fastpath.joins import (
    _EMPTY_REL,
    _join_all,
)
from gateway.stream.fastpath.rows import (
    _grouped_rows,
    _plain_rows,
)
from gateway.stream.fastpath.values import (
    RunContext,
    _ebv,
)

# ---------------------------------------------------------------------------------------------
# Running a plan on a window.


def run_plan(plan: Plan, window: WindowData) -> Evaluation:
    """Evaluate ``plan`` on ``window``; raises :class:`Fallback` when the data needs the general path."""
    table = plan.table
    if len(table) > term_limit(window):
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


def term_limit(window: WindowData) -> int:
    """How many terms the plan's table may hold before ``window`` is encoded.

    Why a limit tied to the window: the table gives every term it has seen an id, and a stream
    names new terms all the time (each Entrance reading its own message node and one node per
    customer's position at that time). Kept for ever, that was the soak's leak: ~3 pyoxigraph
    nodes per reading while the fast path ran on every window (docs/benchmarks.md, "Soak"). A
    window needs at most two new terms per triple it holds (its own and the static graph's), so a
    table past :data:`TERMS_SLACK` times that is mostly terms of windows gone by: it is emptied and
    this window's terms get new ids (the sealed panes' cached encodings are keyed by the table's
    generation, so they are encoded again). Emptying costs one window's encoding, once every
    ``TERMS_SLACK - 1`` windows' worth of new terms at most."""
    return max(TERMS_FLOOR, TERMS_SLACK * 2 * (len(window.stamped) + len(window.static)))


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
