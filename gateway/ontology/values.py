"""One data value of the ontology, changed in place: checked against its xsd type, then written into
the Turtle text where it stands.

Why edit the text and not re-serialise a graph: the ontology is a hand-written file with comments
and an order people rely on ("each value on one line"); a new version must differ from the old by
exactly that one value, so its diff in the history reads like the owner's change. The edited text
is parsed again and compared with the expected graph, so a text edit can never change anything else.
"""

from __future__ import annotations

import re
from decimal import Decimal, InvalidOperation

from gateway.ontology.model import XSD, OntologyModel

_NUMBER = {
    "decimal": re.compile(r"[+-]?(\d+(\.\d*)?|\.\d+)"),
    "integer": re.compile(r"[+-]?\d+"),
    "int": re.compile(r"[+-]?\d+"),
    "long": re.compile(r"[+-]?\d+"),
    "short": re.compile(r"[+-]?\d+"),
    "nonNegativeInteger": re.compile(r"\+?\d+"),
    "positiveInteger": re.compile(r"\+?0*[1-9]\d*"),
    "double": re.compile(r"[+-]?((\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?|INF|NaN)"),
    "float": re.compile(r"[+-]?((\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?|INF|NaN)"),
}
_BOOLEAN = ("true", "false", "1", "0")
TYPES = tuple(_NUMBER) + ("boolean", "string")


class ValueInvalid(ValueError):
    """A value that does not fit: ``field`` names the input, the message what is wrong."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(message)
        self.field, self.message = field, message

    def to_dict(self) -> dict[str, str]:
        return {"field": self.field, "message": self.message}


_WHOLE = ("integer", "int", "long", "short")
_WORDS = {**{t: "a whole number" for t in _WHOLE}, "nonNegativeInteger": "a whole number, 0 or more",
          "positiveInteger": "a whole number, 1 or more", "decimal": "a number", "double": "a number",
          "float": "a number", "boolean": "true or false", "string": "text"}


def _limits_words(limits: dict[str, str]) -> str:
    low, high = limits.get("minInclusive"), limits.get("maxInclusive")
    if low is not None and high is not None:
        return f" from {low} to {high}"
    parts = []
    if low is not None:
        parts.append(f"at least {low}")
    if limits.get("minExclusive") is not None:
        parts.append(f"more than {limits['minExclusive']}")
    if high is not None:
        parts.append(f"at most {high}")
    if limits.get("maxExclusive") is not None:
        parts.append(f"less than {limits['maxExclusive']}")
    return (", " + " and ".join(parts)) if parts else ""


def _default_example(datatype: str, limits: dict[str, str]) -> str:
    """A plain example within the limits: 1.2 (3 for whole numbers), else a limit itself."""
    plain = "3" if datatype in _WHOLE else "1.2"
    n = Decimal(plain)
    fits = not ((("minInclusive" in limits) and n < Decimal(limits["minInclusive"]))
                or (("maxInclusive" in limits) and n > Decimal(limits["maxInclusive"]))
                or (("minExclusive" in limits) and n <= Decimal(limits["minExclusive"]))
                or (("maxExclusive" in limits) and n >= Decimal(limits["maxExclusive"])))
    return plain if fits else limits.get("minInclusive") or limits.get("maxInclusive") or plain


def expectation(datatype: str, unit: str = "", limits: dict[str, str] | None = None, example: str = "") -> str:
    """What a value must be, in an owner's words: "a number in metres from 0 to 5, e.g. 1.2"."""
    words = _WORDS.get(datatype, f"a value of type {datatype}")
    if unit:
        words += f" in {unit}"
    words += _limits_words(limits or {})
    if not example and datatype in _NUMBER:
        example = _default_example(datatype, limits or {})
    if example and datatype != "boolean":
        words += f", e.g. {example}"
    return words


def check_limits(prop: str, lexical: str, datatype: str, unit: str, limits: dict[str, str], example: str = "") -> None:
    """ValueInvalid when a number lies outside the property's declared limits, saying which and why."""
    if datatype not in _NUMBER or not limits:
        return
    try:
        number = Decimal(lexical)
    except InvalidOperation:
        return  # INF / NaN: the type check said what it could
    unit_words = f" {unit}" if unit else ""
    tests = (("minInclusive", lambda b: number < b, "below the least allowed,"),
             ("minExclusive", lambda b: number <= b, "not more than"),
             ("maxInclusive", lambda b: number > b, "above the most allowed,"),
             ("maxExclusive", lambda b: number >= b, "not less than"))
    for facet, broken, words in tests:
        bound = limits.get(facet)
        if bound is not None and broken(Decimal(bound)):
            raise ValueInvalid("value", f"{prop}: {lexical}{unit_words} is {words} {bound}{unit_words}; "
                                        f"give {expectation(datatype, unit, limits, example)}")


def lexical_form(prop: str, datatype: str, value: object, unit: str = "", limits: dict[str, str] | None = None,
                 example: str = "") -> str:
    """The canonical-enough lexical form of ``value`` for ``xsd:<datatype>``, or ValueInvalid saying,
    in words, what is expected (``unit`` and ``limits`` from the ontology; ``example``: e.g. the
    value it has now)."""
    raw = ("true" if value else "false") if isinstance(value, bool) else str(value).strip()
    expects = expectation(datatype, unit, limits, example)
    if datatype in _NUMBER:
        if not _NUMBER[datatype].fullmatch(raw):
            raise ValueInvalid("value", f"{prop}: {raw!r} is not {expects}")
        if datatype == "decimal":
            try:
                Decimal(raw)
            except InvalidOperation:
                raise ValueInvalid("value", f"{prop}: {raw!r} is not {expects}") from None
        check_limits(prop, raw, datatype, unit, limits or {}, example)
        return raw
    if datatype == "boolean":
        if raw not in _BOOLEAN:
            raise ValueInvalid("value", f"{prop}: {raw!r} is not {expects}")
        return "true" if raw in ("true", "1") else "false"
    if len(raw) > 10_000:
        raise ValueInvalid("value", f"{prop}: a value may have at most 10000 characters")
    return str(value)


def value_type(model: OntologyModel, individual: str, prop: str) -> str:
    """The xsd type a value of ``prop`` must have: the property's range, else the type it has now."""
    info = model.properties.get(prop)
    if info and info.range:
        return info.range
    current = next((v for v in model.individuals[individual].values if v.property == prop), None)
    return current.datatype if current else "string"


def _turtle_literal(lexical: str, datatype: str, xsd_prefix: str | None) -> str:
    escaped = lexical.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n").replace("\r", "\\r")
    if datatype == "string":
        return f'"{escaped}"'
    return f'"{escaped}"^^' + (f"{xsd_prefix}:{datatype}" if xsd_prefix is not None else f"<{XSD}{datatype}>")


def _prefixes(text: str, namespace: str) -> list[str]:
    return [m.group(1) for m in re.finditer(r"@prefix\s+([\w-]*):\s*<([^>]*)>\s*\.", text, re.IGNORECASE) if m.group(2) == namespace] + \
        [m.group(1) for m in re.finditer(r"(?im)^\s*PREFIX\s+([\w-]*):\s*<([^>]*)>", text) if m.group(2) == namespace]


def _names(text: str, base: str, local_name: str) -> str:
    """A regex alternative matching the term as written: ``prefix:name`` or ``<full IRI>``."""
    forms = [re.escape(f"{p}:{local_name}") for p in _prefixes(text, base)] + [re.escape(f"<{base}{local_name}>")]
    return "(?:" + "|".join(forms) + ")"


def _statement_end(text: str, start: int) -> int:
    """Index of the '.' ending the Turtle statement that begins at ``start`` (strings, IRIs and
    comments skipped; a '.' inside a number is followed by a digit)."""
    i, n = start, len(text)
    while i < n:
        ch = text[i]
        if ch == "#":
            i = text.find("\n", i)
            i = n if i < 0 else i
        elif ch == "<":
            i = text.index(">", i)
        elif ch in "\"'":
            quote = ch * 3 if text.startswith(ch * 3, i) else ch
            j = i + len(quote)
            while True:
                j = text.index(quote, j)
                if text[j - 1] != "\\" or text[j - 2] == "\\":
                    break
                j += 1
            i = j + len(quote) - 1
        elif ch == "." and (i + 1 >= n or text[i + 1] in " \t\r\n#"):
            return i
        i += 1
    raise ValueError("statement without its final '.'")


_LITERAL = r'(?:"(?:[^"\\\n]|\\.)*"(?:\^\^(?:<[^>]*>|[\w-]*:[\w-]*)|@[\w-]+)?|[+-]?[\d.]+(?:[eE][+-]?\d+)?|true|false)'


def set_value_in_text(text: str, model: OntologyModel, individual: str, prop: str, lexical: str, datatype: str) -> str:
    """``text`` with the one value of ``individual.prop`` replaced (or added) — nothing else changed."""
    import rdflib
    from rdflib.compare import isomorphic

    base = model.base
    xsd_prefix = next(iter(_prefixes(text, XSD)), None)
    literal = _turtle_literal(lexical, datatype, xsd_prefix)
    subject = re.search(r"(?m)^[ \t]*" + _names(text, base, individual) + r"(?=[\s;,])", text)
    if subject is None:
        raise ValueInvalid("individual", f"{individual}: its statements are not where the editor can change them")
    end = _statement_end(text, subject.end())
    statement = text[subject.start():end]
    pattern = re.compile(r"(?<![\w:-])(" + _names(text, base, prop) + r"\s+)" + _LITERAL)
    found = list(pattern.finditer(statement))
    if len(found) > 1:
        raise ValueInvalid("property", f"{individual}.{prop} has {len(found)} values; edit the ontology text instead")
    if found:
        m = found[0]
        statement = statement[:m.start()] + m.group(1) + literal + statement[m.end():]
    else:
        prefix = next(iter(_prefixes(text, base)), None)
        term = f"{prefix}:{prop}" if prefix is not None else f"<{base}{prop}>"
        statement = statement.rstrip() + f" ;\n    {term} {literal} "
    new_text = text[:subject.start()] + statement + text[end:]

    old, new = rdflib.Graph(), rdflib.Graph()
    old.parse(data=text, format="turtle")
    new.parse(data=new_text, format="turtle")
    s, p = rdflib.URIRef(base + individual), rdflib.URIRef(base + prop)
    old.remove((s, p, None))
    old.add((s, p, rdflib.Literal(lexical, datatype=None if datatype == "string" else rdflib.URIRef(XSD + datatype))))
    if not isomorphic(old, new):
        raise ValueInvalid("value", f"{individual}.{prop}: the value could not be changed in place; edit the ontology text instead")
    return new_text
