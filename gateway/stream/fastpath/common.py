"""Constants, errors and the term table of the fast path (terms as integers)."""

from __future__ import annotations

import decimal
import itertools
from decimal import Decimal

import numpy as np
from pyoxigraph import BlankNode, NamedNode

from gateway.rdf.terms import (
    XSD,
    Term,
)

SCALE = 9  # fractional digits of the fixed-point numbers
MAX_ABS_UNITS = 10**15  # |value| <= 10**6 at SCALE
LIMIT = 2**62  # headroom below int64 for every intermediate
NO_TS = np.iinfo(np.int64).min
MAX_ROWS = 30_000_000  # intermediate solutions; beyond this the window goes the general way
TERMS_FLOOR = 4_096
TERMS_SLACK = 4
"""A plan's term table is emptied before a window when it holds more than ``TERMS_SLACK`` times the
terms that window can need (two per triple, its own and the static graph's), and at least
``TERMS_FLOOR``: see :func:`gateway.stream.fastpath.executor.run_plan`."""
# what a term is, per id: an exact integer / decimal (fixed-point value known), an IRI or blank
# node, a simple string, anything else (doubles, dates, language strings …: never decided here)
KIND_INT = 0
KIND_DEC = 1
KIND_IRI = 2
KIND_STR = 3
KIND_OTHER = 4
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
