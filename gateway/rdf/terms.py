"""RDF terms: the namespaces of the teahouse, and conversions between JSON values and RDF terms.

Why pyoxigraph terms everywhere: the stream engine loads window contents into pyoxigraph stores and
the fast path reads literal values directly, so one term type avoids conversions on the hot path.
Numbers become ``xsd:decimal`` (exact: ``2.6 - 2.5 > 0.1`` is false, as a sensor threshold means),
never ``xsd:double``; integers stay ``xsd:integer``.

Lexical forms: :func:`canonical_term` applies the XSD 1.1 canonical mappings (``"03"`` → ``"3"``,
``"3.10"``/``"3.0"`` decimal → ``"3.1"``/``"3"``, ``"1"`` boolean → ``"true"``, ``"10"`` double →
``"1.0E1"``) and, as RDF stores do (pyoxigraph, Jena TDB1, Stardog), writes the integer-derived
datatypes (``xsd:int``, ``xsd:long`` …) as ``xsd:integer``. The stream engine applies it to every
literal it ingests and every term it returns, on both evaluation paths, so two paths (or two
runs) can be compared term by term. :func:`term_to_sparql_json` is the SPARQL 1.1 Query Results
JSON form of a term.
"""

from __future__ import annotations

import math
import re
from decimal import Decimal, InvalidOperation
from typing import Any, Union

from pyoxigraph import BlankNode, Literal, NamedNode

Term = Union[NamedNode, BlankNode, Literal]
Triple = tuple[Term, Term, Term]

PRINTEPS = "http://printeps.org/cafe/entrance/"
RDF = "http://www.w3.org/1999/02/22-rdf-syntax-ns#"
RDFS = "http://www.w3.org/2000/01/rdf-schema#"
OWL = "http://www.w3.org/2002/07/owl#"
XSD = "http://www.w3.org/2001/XMLSchema#"
CSPARQL_FN = "http://larkc.eu/csparql/sparql/jena/ext#"

RDF_TYPE = NamedNode(RDF + "type")
XSD_DECIMAL = NamedNode(XSD + "decimal")
XSD_INTEGER = NamedNode(XSD + "integer")
XSD_DOUBLE = NamedNode(XSD + "double")
XSD_BOOLEAN = NamedNode(XSD + "boolean")
XSD_STRING = NamedNode(XSD + "string")
XSD_FLOAT = NamedNode(XSD + "float")
RDF_LANG_STRING = RDF + "langString"

# Prefixes understood in REST triples ("printeps:Customer") and in query results shortening.
DEFAULT_PREFIXES = {
    "printeps": PRINTEPS,
    "rdf": RDF,
    "rdfs": RDFS,
    "owl": OWL,
    "xsd": XSD,
    "f": CSPARQL_FN,
}

NUMERIC_DATATYPES = {
    XSD + name for name in (
        "integer", "decimal", "int", "long", "short", "byte", "nonNegativeInteger", "positiveInteger",
        "negativeInteger", "nonPositiveInteger", "unsignedInt", "unsignedLong", "unsignedShort",
        "unsignedByte",
    )
}

_PNAME = re.compile(r"^([A-Za-z][\w.-]*)?:([\w.:%-]*)$")


class TermError(ValueError):
    """A value that cannot become an RDF term; ``where`` names the place (e.g. ``triples[3][2]``)."""

    def __init__(self, where: str, message: str) -> None:
        super().__init__(f"{where}: {message}")
        self.where = where
        self.message = message


def decimal_literal(value: Decimal | int | float | str) -> Literal:
    """An ``xsd:decimal`` literal; floats go through ``repr`` so 2.5 stays "2.5" (not 2.4999…)."""
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"{value!r} is not a finite number")
        value = Decimal(repr(value))
    dec = Decimal(value)
    text = format(dec, "f")
    if "." in text:
        text = text.rstrip("0").rstrip(".") or "0"
    return Literal(text, datatype=XSD_DECIMAL)


def value_to_term(value: Any, where: str = "value") -> Term:
    """A JSON value as an RDF term (objects of mapped triples): numbers, booleans, strings."""
    if isinstance(value, bool):
        return Literal("true" if value else "false", datatype=XSD_BOOLEAN)
    if isinstance(value, int):
        return Literal(str(value), datatype=XSD_INTEGER)
    if isinstance(value, (float, Decimal)):
        try:
            return decimal_literal(value)
        except (ValueError, InvalidOperation) as exc:
            raise TermError(where, str(exc)) from None
    if isinstance(value, str):
        return Literal(value)
    raise TermError(where, f"a {type(value).__name__} cannot be an RDF literal")


def parse_node(text: str, where: str, prefixes: dict[str, str] | None = None) -> NamedNode | BlankNode:
    """A subject/predicate written as ``<iri>``, ``prefix:local``, ``_:label`` or a bare absolute IRI."""
    prefixes = DEFAULT_PREFIXES if prefixes is None else prefixes
    if not isinstance(text, str) or not text:
        raise TermError(where, f"expected an IRI string, got {text!r}")
    if text.startswith("_:"):
        return BlankNode(text[2:])
    if text.startswith("<") and text.endswith(">"):
        return _named(text[1:-1], where)
    match = _PNAME.match(text)
    if match and "://" not in text:
        prefix = match.group(1) or ""
        if prefix not in prefixes:
            raise TermError(where, f"unknown prefix {prefix!r} in {text!r}")
        return _named(prefixes[prefix] + match.group(2), where)
    if re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:", text):
        return _named(text, where)
    raise TermError(where, f"{text!r} is not an IRI (<…>, prefix:local or _:label)")


def _named(iri: str, where: str) -> NamedNode:
    try:
        return NamedNode(iri)
    except ValueError as exc:
        raise TermError(where, f"invalid IRI {iri!r}: {exc}") from None


def parse_object(value: Any, where: str, prefixes: dict[str, str] | None = None) -> Term:
    """A triple's object from JSON: a node string (``<…>``, ``p:x``, ``_:b``), a number/bool,
    ``{"value": "…", "datatype": "xsd:…"}`` / ``{"value": "…", "lang": "en"}``, or ``"\\"text\\""``
    (a quoted string is a plain literal)."""
    if isinstance(value, dict):
        if "value" not in value:
            raise TermError(where, "a literal object needs a 'value'")
        lexical = str(value["value"]).lower() if isinstance(value["value"], bool) else str(value["value"])
        if value.get("lang"):
            return Literal(lexical, language=str(value["lang"]))
        if value.get("datatype"):
            datatype = parse_node(str(value["datatype"]), f"{where}.datatype", prefixes)
            try:
                return Literal(lexical, datatype=datatype)  # type: ignore[arg-type]
            except ValueError as exc:
                raise TermError(where, str(exc)) from None
        return Literal(lexical)
    if isinstance(value, str):
        if len(value) >= 2 and value[0] == '"' and value[-1] == '"':
            return Literal(value[1:-1])
        return parse_node(value, where, prefixes)
    return value_to_term(value, where)


def parse_triple(raw: Any, where: str, prefixes: dict[str, str] | None = None) -> Triple:
    """One ``[s, p, o]`` triple from JSON, with a clear error naming the element that is wrong."""
    if not isinstance(raw, (list, tuple)) or len(raw) != 3:
        raise TermError(where, f"a triple must be a list [subject, predicate, object], got {raw!r:.80}")
    s = parse_node(raw[0], f"{where}[0]", prefixes)
    p = parse_node(raw[1], f"{where}[1]", prefixes)
    if isinstance(p, BlankNode):
        raise TermError(f"{where}[1]", "a predicate cannot be a blank node")
    o = parse_object(raw[2], f"{where}[2]", prefixes)
    return (s, p, o)


def term_to_json(term: Term | None) -> Any:
    """A term as a JSON value: IRIs as strings, numbers as numbers, booleans, plain strings."""
    if term is None:
        return None
    if isinstance(term, NamedNode):
        return term.value
    if isinstance(term, BlankNode):
        return "_:" + term.value
    datatype = term.datatype.value if term.datatype is not None else XSD + "string"
    if datatype in NUMERIC_DATATYPES:
        try:
            dec = Decimal(term.value)
        except InvalidOperation:
            return term.value
        return int(dec) if dec == dec.to_integral_value() and "." not in term.value else float(dec)
    if datatype in (XSD + "double", XSD + "float"):
        try:
            return float(term.value)
        except ValueError:
            return term.value
    if datatype == XSD + "boolean":
        return term.value in ("true", "1")
    return term.value


def local_name(iri: str) -> str:
    """The part after the last ``#`` or ``/`` (``…/entrance/c1`` → ``c1``)."""
    cut = max(iri.rfind("#"), iri.rfind("/"))
    return iri[cut + 1:] if cut >= 0 and cut < len(iri) - 1 else iri


# -- XSD 1.1 canonical lexical forms -------------------------------------------------------------

INTEGER_DERIVED = {
    XSD + name for name in (
        "int", "long", "short", "byte", "nonNegativeInteger", "positiveInteger", "negativeInteger",
        "nonPositiveInteger", "unsignedInt", "unsignedLong", "unsignedShort", "unsignedByte",
    )
}
_INTEGER_RE = re.compile(r"^[+-]?[0-9]+$")
_DECIMAL_RE = re.compile(r"^[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)$")
_DOUBLE_RE = re.compile(r"^(?:[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?|[+-]?INF|NaN)$")
_CANONICAL_CACHE: dict[Literal, Literal] = {}
_CANONICAL_CACHE_MAX = 100_000


def canonical_integer(value: int) -> str:
    return str(value)


def canonical_decimal(value: Decimal) -> str:
    """XSD 1.1 decimalCanonicalMap: no '+', no leading/trailing zeros, no point for integers."""
    if value == value.to_integral_value():
        return str(int(value))
    text = format(value, "f").rstrip("0")
    sign = "-" if text.startswith("-") else ""
    text = text.lstrip("-")
    if text.startswith("."):
        text = "0" + text
    return sign + text


def canonical_double(value: float) -> str:
    """XSD 1.1 doubleCanonicalMap: ``1.0E1``, ``1.25E-3``, ``0.0E0``, ``-0.0E0``, ``INF``, ``NaN``."""
    if math.isnan(value):
        return "NaN"
    if math.isinf(value):
        return "INF" if value > 0 else "-INF"
    if value == 0:
        return "-0.0E0" if math.copysign(1.0, value) < 0 else "0.0E0"
    sign, digits, exponent = Decimal(repr(value)).normalize().as_tuple()
    text = "".join(map(str, digits))
    exp = exponent + len(text) - 1  # type: ignore[operator]
    mantissa = text[0] + "." + (text[1:] or "0")
    return ("-" if sign else "") + mantissa + "E" + str(exp)


def _canonical_float(lexical: str) -> str:
    import numpy as np

    value = np.float32(float(lexical.replace("INF", "inf")))
    if not np.isfinite(value) or value == 0:
        return canonical_double(float(value))
    # the shortest decimal that reads back as the same float32
    text = np.format_float_scientific(value, unique=True, trim="0", exp_digits=1)
    mantissa, exp = text.split("e")
    if "." not in mantissa:
        mantissa += ".0"
    return f"{mantissa}E{int(exp)}"


def canonical_term(term: Term) -> Term:
    """The XSD 1.1 canonical form of a literal (other terms unchanged); ill-typed literals unchanged.

    Why one function: the general path (pyoxigraph rewrites numbers to its own forms when it
    stores them) and the fast path must hand back identical terms, and f:timestamp must find a
    triple whatever the lexical form it was posted with."""
    if not isinstance(term, Literal):
        return term
    cached = _CANONICAL_CACHE.get(term)
    if cached is not None:
        return cached
    result = _canonical(term)
    if len(_CANONICAL_CACHE) >= _CANONICAL_CACHE_MAX:
        _CANONICAL_CACHE.clear()
    _CANONICAL_CACHE[term] = result
    return result


def _canonical(term: Literal) -> Literal:
    if term.language:
        return term
    datatype = term.datatype.value
    lexical = term.value.strip() if datatype != XSD + "string" else term.value
    try:
        if datatype == XSD + "integer" or datatype in INTEGER_DERIVED:
            if not _INTEGER_RE.match(lexical):
                return term
            return Literal(canonical_integer(int(lexical)), datatype=XSD_INTEGER)
        if datatype == XSD + "decimal":
            if not _DECIMAL_RE.match(lexical):
                return term
            return Literal(canonical_decimal(Decimal(lexical)), datatype=XSD_DECIMAL)
        if datatype == XSD + "boolean":
            if lexical in ("true", "1"):
                return Literal("true", datatype=XSD_BOOLEAN)
            if lexical in ("false", "0"):
                return Literal("false", datatype=XSD_BOOLEAN)
            return term
        if datatype == XSD + "double":
            if not _DOUBLE_RE.match(lexical):
                return term
            return Literal(canonical_double(float(lexical.replace("INF", "inf"))), datatype=XSD_DOUBLE)
        if datatype == XSD + "float":
            if not _DOUBLE_RE.match(lexical):
                return term
            return Literal(_canonical_float(lexical), datatype=XSD_FLOAT)
    except (ValueError, InvalidOperation, OverflowError):
        return term
    return term


def canonical_triple(triple: Triple) -> Triple:
    """The triple with a canonical object (subjects and predicates are never literals)."""
    o = triple[2]
    if isinstance(o, Literal):
        c = canonical_term(o)
        if c is not o:
            return (triple[0], triple[1], c)
    return triple


def term_to_sparql_json(term: Term) -> dict[str, str]:
    """A term in the SPARQL 1.1 Query Results JSON format (``type``, ``value``, ``datatype``,
    ``xml:lang``). Simple literals (``xsd:string``) carry no datatype, language-tagged ones only
    ``xml:lang`` (RDF 1.1: their datatype is always rdf:langString)."""
    if isinstance(term, NamedNode):
        return {"type": "uri", "value": term.value}
    if isinstance(term, BlankNode):
        return {"type": "bnode", "value": term.value}
    out = {"type": "literal", "value": term.value}
    if term.language:
        out["xml:lang"] = term.language
    elif term.datatype is not None and term.datatype.value != XSD + "string":
        out["datatype"] = term.datatype.value
    return out


def term_from_sparql_json(data: dict[str, str]) -> Term:
    """The inverse of :func:`term_to_sparql_json` (for clients and tests)."""
    kind = data.get("type")
    if kind == "uri":
        return NamedNode(data["value"])
    if kind == "bnode":
        return BlankNode(data["value"])
    if kind in ("literal", "typed-literal"):
        if data.get("xml:lang"):
            return Literal(data["value"], language=data["xml:lang"])
        if data.get("datatype"):
            return Literal(data["value"], datatype=NamedNode(data["datatype"]))
        return Literal(data["value"])
    raise ValueError(f"not a SPARQL JSON term: {data!r}")
