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

The package: ``common`` (constants, errors, the term table), ``values`` (columns, frames, SPARQL
operators), ``compiler`` (algebra → plan), ``joins`` (scans, greedy joins, band joins), ``rows``
(projection, aggregates, HAVING), ``executor`` (a plan on a window).
"""

from gateway.stream.fastpath.common import Fallback, NotCompilable, TermTable
from gateway.stream.fastpath.compiler import Plan, compile_query
from gateway.stream.fastpath.executor import run_plan

__all__ = ["Fallback", "NotCompilable", "Plan", "TermTable", "compile_query", "run_plan"]
