"""Rules of the plain shapes, described for building at run time without code generation.

Why: Drools' executable model generates and compiles Java for every rule (~11 ms of CPU a rule:
two minutes for 10,000), while the model objects it would build take microseconds. Most rules of a
large table are of a few plain shapes: patterns on declared or imported types whose constraints
compare a field with a literal, with a field of an earlier pattern or with a bound field
(``$id : id`` … ``applicant == $id``), ``in``/``not in`` lists, ``matches``/``not matches``,
``not``/``exists`` over one pattern, accumulates (``accumulate( …; $t : sum( $a ); … )`` and
``Number( … ) from accumulate( …, count( 1 ) | sum | min | max( $v ) )``), the attributes
``salience``, ``agenda-group``, ``activation-group``, ``auto-focus``, ``no-loop``,
``lock-on-active``, ``date-effective`` and ``date-expires``, and a then-part of calls on a global
whose arguments are literals (``1L`` too), bound variables, their getters, static calls of a
``java.lang`` class the rule policy allows (``String.format("%s|%d", $a.getId(),
Math.max($a.getAge(), 1L))``; the Java side chooses each method as javac does), or texts joined
from those with ``+`` (``actions.say("bot", "Welcome " + $c.getName())``). This module recognises exactly those,
strictly, and describes them as JSON for the Java side (``org.printeps.gateway.PlainRules``), which
builds the same ``Rule`` objects the generated code would (same indexes, constraint ids, property
reactivity, operators and accumulate functions). Anything else — another operator, a method call
in a constraint, ``from`` a collection, ``eval``, another attribute, a then-part with Java beyond
such calls, a string with escapes — is left to Drools' compiler, which also reports its errors with
file, line and column. So is any rule the Java side cannot build exactly (an unknown field, a
literal of another type, an ambiguous or generic method, a class name the rule's package or imports
would hide). :func:`why_not` says why a rule is not plain.
"""

from __future__ import annotations

import json
import re
from collections import Counter
from typing import Any

from gateway.engine.drl_items import Item, SourceItems, identifiers
from gateway.engine.policy import REFLECTION_MEMBERS, RulePolicy

FORMAT = 3  # org.printeps.gateway.PlainRules.FORMAT (2: not/exists, in, matches, from accumulate, attributes;
#             3: static calls of the rule policy's java.lang classes and long literals in then-parts)

#: The rule policy's allowed classes: a then-part's static call goes plain only on one of these
#: (``String.format``, ``Math.max``…), never on a class an author could not name anyway.
_POLICY = RulePolicy()

_TOKEN = re.compile(
    r"""
     (?P<space>\s+)
    |(?P<comment>//[^\n]*|/\*.*?\*/)
    |(?P<string>"[^"\\\n]*")
    |(?P<number>\d+(?:\.\d+)?L?(?![\w.]))
    |(?P<name>\$?[A-Za-z_][A-Za-z0-9_]*)
    |(?P<punct>==|!=|>=|<=|[<>:;,().\-*+])
    """,
    re.X | re.S,
)
OPERATORS = {"==", "!=", ">", ">=", "<", "<="}
KEYWORDS = {
    "not", "exists", "eval", "forall", "from", "collect", "or", "and", "over", "window", "entry", "in", "matches",
    "memberOf", "contains", "soundslike", "excludes", "this", "null", "new", "accumulate", "when", "then", "end",
    "rule", "query", "if", "do", "break", "modify", "insert", "update", "delete", "retract",
}


TEXT_ATTRIBUTES = ("agenda-group", "activation-group", "date-effective", "date-expires")
FLAG_ATTRIBUTES = ("auto-focus", "no-loop", "lock-on-active")


class NotPlain(Exception):
    """The text is not of a plain shape (the rule goes to Drools' compiler)."""


def tokens(text: str) -> list[tuple[str, str]]:
    """(kind, text) of every token but spaces and comments; NotPlain on any other character."""
    out: list[tuple[str, str]] = []
    pos = 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            if text[pos].isdigit():
                raise NotPlain("a number with a suffix, exponent or radix (1L, 1e3, 0x1)")
            raise NotPlain(f"character {text[pos]!r}")
        kind = m.lastgroup or ""
        if kind not in ("space", "comment"):
            out.append((kind, m.group()))
        pos = m.end()
    return out


def package_imports(sources: list[SourceItems]) -> dict[str, list[str] | None]:
    """The imports of each package (DRL imports are package-wide), or None for a package whose
    header holds more than package, import and global statements (attributes, functions imports…):
    its rules are all left to the compiler."""
    out: dict[str, list[str] | None] = {}
    for src in sources:
        try:
            imports = _header_imports(src.header())
        except NotPlain:
            out[src.package] = None
            continue
        known = out.setdefault(src.package, [])
        if known is not None:
            known.extend(i for i in imports if i not in known)
    return out


def _header_imports(header: str) -> list[str]:
    toks = tokens(header)
    imports: list[str] = []
    k = 0
    while k < len(toks):
        word = toks[k][1]
        if word == "package":
            k = _dotted(toks, k + 1)[1]
        elif word == "import":
            name, k = _dotted(toks, k + 1, star=True)
            if name in ("function", "static") or name.startswith(("function.", "static.")):
                raise NotPlain("import function/static")
            imports.append(name)
        elif word == "global":
            _, k = _dotted(toks, k + 1)
            if k >= len(toks) or toks[k][0] != "name":
                raise NotPlain("global")
            k += 1
        else:
            raise NotPlain(f"header statement {word!r}")
        if k < len(toks) and toks[k][1] == ";":
            k += 1
    return imports


def _dotted(toks: list[tuple[str, str]], k: int, star: bool = False) -> tuple[str, int]:
    if k >= len(toks) or toks[k][0] != "name":
        raise NotPlain("a name was expected")
    parts = [toks[k][1]]
    k += 1
    while k + 1 < len(toks) and toks[k][1] == "." and (toks[k + 1][0] == "name" or (star and toks[k + 1][1] == "*")):
        parts.append(toks[k + 1][1])
        k += 2
    return ".".join(parts), k


def describe(src: SourceItems, item: Item, imports: list[str]) -> dict[str, Any] | None:
    """The description of rule ``item`` for PlainRules, or None if it is not of a plain shape."""
    try:
        return _describe(src, item, imports)
    except NotPlain:
        return None


def queries_apart(sources: list[SourceItems]) -> dict[tuple[str, int], dict[str, Any]]:
    """The queries that build plain, in units of their own instead of the declarations unit, by
    (file, start), each with its description: without parameters, of the plain shapes, and named by
    no other item (no rule or query calls them, so no other unit needs them to compile). Why:
    explain's diagnostic queries are hundreds of such queries per version; compiled with the
    declarations they took ~6 s of CPU and ~250 MB of heap for 100 rules."""
    if not any(item.kind == "query" for src in sources for item in src.items):
        return {}
    words = {(src.file, item.start): identifiers(src.item_text(item)) for src in sources for item in src.items}
    named: Counter[str] = Counter(word for found in words.values() for word in found)
    imports = package_imports(sources)
    apart: dict[tuple[str, int], dict[str, Any]] = {}
    for src in sources:
        package_imports_ = imports.get(src.package)
        for item in src.items:
            if item.kind != "query" or package_imports_ is None:
                continue
            if named[item.name] - (item.name in words[(src.file, item.start)]) == 0:  # no other item names it
                spec = describe(src, item, package_imports_)
                if spec is not None:
                    apart[(src.file, item.start)] = spec
    return apart


def queries_only(spec: bytes) -> bool:
    """Whether a plain unit's description (:func:`spec_json`) holds queries, no rule."""
    return b'"query":true' in spec and all(one.get("query") for one in json.loads(spec)["rules"])


def why_not(src: SourceItems, item: Item, imports: list[str] | None) -> str | None:
    """Why rule ``item`` is not of a plain shape (the first thing the reader met that it does not
    take), or None if it is. Why: which shapes of a rule base go to the slow compiler is what decides
    its cold build time; this is the diagnostic that shows it (:func:`reasons`)."""
    if imports is None:
        return "a package header with more than package, import and global statements"
    try:
        _describe(src, item, imports)
    except NotPlain as e:
        return str(e)
    return None


def reasons(sources: list[SourceItems]) -> Counter[str]:
    """How many rules of ``sources`` are plain (key ``"plain"``) and, for the others, how many
    stop at each reason (:func:`why_not`): the split a benchmark reports next to its build times."""
    imports = package_imports(sources)
    out: Counter[str] = Counter()
    for src in sources:
        for item in src.rules:
            out[why_not(src, item, imports.get(src.package)) or "plain"] += 1
    return out


def _describe(src: SourceItems, item: Item, imports: list[str]) -> dict[str, Any]:
    parser = _Parser(tokens(src.item_text(item)))
    if item.kind == "query":
        return parser.query(src.package, item.name, imports)
    return parser.rule(src.package, item.name, imports)


def spec_json(rules: list[dict[str, Any]]) -> bytes:
    """The description of a unit of plain rules (what its cache entry holds)."""
    return json.dumps({"format": FORMAT, "rules": rules}, separators=(",", ":"), sort_keys=True).encode()


class _Parser:
    """A strict recursive-descent reader of one rule's tokens (see the module docstring)."""

    def __init__(self, toks: list[tuple[str, str]]):
        self.toks = toks
        self.k = 0
        self.fields: set[str] = set()  # variables bound to a field ($id : id) by the patterns read so far

    # ---- token helpers
    def peek(self, ahead: int = 0) -> tuple[str, str]:
        k = self.k + ahead
        return self.toks[k] if k < len(self.toks) else ("eof", "")

    def take(self, text: str | None = None, kind: str | None = None) -> str:
        tok_kind, tok = self.peek()
        if (text is not None and tok != text) or (kind is not None and tok_kind != kind) or tok_kind == "eof":
            raise NotPlain(f"expected {text or kind}, found {tok!r}")
        self.k += 1
        return tok

    def name(self) -> str:
        word = self.take(kind="name")
        if word in KEYWORDS:
            raise NotPlain(f"keyword {word}")
        return word

    # ---- grammar
    def rule(self, package: str, name: str, imports: list[str]) -> dict[str, Any]:
        self.take("rule")
        self.take(kind="string" if self.peek()[0] == "string" else "name")
        salience = None
        attributes: dict[str, Any] = {}
        while self.peek()[1] != "when":
            attribute = self.attribute_name()
            if attribute in attributes or (attribute == "salience" and salience is not None):
                raise NotPlain(f"two {attribute} attributes")
            if attribute == "salience":
                salience = self.integer()
            elif attribute in TEXT_ATTRIBUTES:
                attributes[attribute] = self.take(kind="string")[1:-1]
            elif attribute in FLAG_ATTRIBUTES:
                attributes[attribute] = self.take() == "true" if self.peek()[1] in ("true", "false") else True
            else:
                raise NotPlain(f"attribute {attribute}")
        self.take("when")
        lhs = []
        while self.peek()[1] != "then":
            lhs.append(self.condition())
        self.take("then")
        rhs = []
        while not (self.peek()[1] == "end" and self.k == len(self.toks) - 1):
            rhs.append(self.call())
        self.take("end")
        if not lhs:
            raise NotPlain("no condition")
        out = {"package": package, "name": name, "salience": salience, "imports": imports, "lhs": lhs, "rhs": rhs}
        if attributes:
            out["attributes"] = attributes
        return out

    def query(self, package: str, name: str, imports: list[str]) -> dict[str, Any]:
        """A query without parameters whose conditions are of the rules' plain shapes (the
        diagnostic queries explain makes are such): built as a rule is, with a query's end."""
        self.take("query")
        self.take(kind="string" if self.peek()[0] == "string" else "name")
        if self.peek()[1] == "(":
            raise NotPlain("a query with parameters")
        lhs = []
        while not (self.peek()[1] == "end" and self.k == len(self.toks) - 1):
            lhs.append(self.condition())
        self.take("end")
        if not lhs:
            raise NotPlain("no condition")
        return {"package": package, "name": name, "query": True, "imports": imports, "lhs": lhs}

    def attribute_name(self) -> str:
        """An attribute's name, with its dashes (``no-loop`` is three tokens)."""
        word = self.take(kind="name")
        while self.peek()[1] == "-" and self.peek(1)[0] == "name":
            self.k += 1
            word += "-" + self.take(kind="name")
        return word

    def integer(self) -> int:
        sign = -1 if self.peek()[1] == "-" and self.take("-") else 1
        digits = self.take(kind="number")
        if "." in digits:
            raise NotPlain("salience must be an integer")
        return sign * int(digits)

    def condition(self) -> dict[str, Any]:
        word = self.peek()[1]
        if word == "accumulate":
            return {"accumulate": self.accumulate()}
        if word in ("not", "exists"):
            self.take(word)
            parens = self.peek()[1] == "("
            if parens:  # not( Type( … ) )
                self.take("(")
            pattern = self.pattern()
            if parens:
                self.take(")")
            if pattern["var"] is not None or pattern["binds"]:
                raise NotPlain(f"a variable bound inside {word}")
            return {word: pattern}
        pattern = self.pattern()
        if self.peek()[1] == "from":
            return {"fromAccumulate": self.from_accumulate(pattern)}
        return {"pattern": pattern}

    def pattern(self) -> dict[str, Any]:
        var = None
        if self.peek()[1].startswith("$") and self.peek(1)[1] == ":":
            var = self.take(kind="name")
            self.take(":")
        type_name = self.type_name()
        self.take("(")
        constraints: list[dict[str, Any]] = []
        binds: list[dict[str, str]] = []
        while self.peek()[1] != ")":
            if constraints or binds:
                self.take(",")
            if self.peek()[1].startswith("$"):
                bound = self.take(kind="name")
                self.take(":")
                binds.append({"var": bound, "field": self.name()})
                if self.peek()[1] not in (",", ")"):
                    raise NotPlain("a binding with a constraint")
            else:
                constraints.append(self.constraint())
        self.take(")")
        self.fields.update(b["var"] for b in binds)
        return {"type": type_name, "var": var, "constraints": constraints, "binds": binds}

    def type_name(self) -> str:
        parts = [self.name()]
        while self.peek()[1] == ".":
            self.take(".")
            parts.append(self.name())
        return ".".join(parts)

    def constraint(self) -> dict[str, Any]:
        field = self.name()
        negated = self.peek()[1] == "not" and self.peek(1)[1] in ("in", "matches")
        if negated:
            self.take("not")
        if self.peek()[1] == "in":
            self.take("in")
            self.take("(")
            literals, texts = [], []
            while True:
                literal, text = self.literal()
                literals.append(literal)
                texts.append(text)
                if self.peek()[1] != ",":
                    break
                self.take(",")
            self.take(")")
            op = "not in" if negated else "in"
            return {"field": field, "op": op, "literals": literals, "text": f"{field} {op} ( {', '.join(texts)} )"}
        if self.peek()[1] == "matches":
            self.take("matches")
            if self.peek()[0] != "string":
                raise NotPlain("matches with something other than a text")
            literal, text = self.literal()
            op = "not matches" if negated else "matches"
            return {"field": field, "op": op, "literal": literal, "text": f"{field} {op} {text}"}
        op = self.take(kind="punct")
        if op not in OPERATORS:
            raise NotPlain(f"operator {op}")
        if self.peek()[1].startswith("$"):
            ref = self.take(kind="name")
            if self.peek()[1] != ".":  # a bound field: applicant == $id
                if ref not in self.fields:
                    raise NotPlain(f"a comparison with {ref}, not a field bound before")
                return {"field": field, "op": op, "ref": ref, "text": f"{field} {op} {ref}"}
            self.take(".")
            ref_field = self.name()
            if self.peek()[1] == ".":
                raise NotPlain("a path deeper than $var.field")
            return {"field": field, "op": op, "ref": ref, "refField": ref_field,
                    "text": f"{field} {op} {ref}.{ref_field}"}
        literal, text = self.literal()
        return {"field": field, "op": op, "literal": literal, "text": f"{field} {op} {text}"}

    def literal(self, long_ok: bool = False) -> tuple[dict[str, Any], str]:
        """A text, boolean or number literal; a long (``1L``) only where ``long_ok`` (a then-part's
        arguments: a constraint's literal is typed by its field, not by a suffix)."""
        kind, tok = self.peek()
        if kind == "string":
            self.k += 1
            return {"s": tok[1:-1]}, tok
        if tok in ("true", "false"):
            self.k += 1
            return {"b": tok == "true"}, tok
        sign = ""
        if tok == "-":
            self.k += 1
            sign = "-"
        digits = self.take(kind="number")
        if len(digits) > 1 and digits[0] == "0" and digits[1] not in ".L":
            raise NotPlain("a number with a leading zero (octal in Java)")
        if digits.endswith("L"):
            if not long_ok or "." in digits:
                raise NotPlain("a number with a suffix, exponent or radix (1L, 1e3, 0x1)")
            return {"l": sign + digits[:-1]}, sign + digits
        return {"n": sign + digits}, sign + digits

    def accumulate(self) -> dict[str, Any]:
        self.take("accumulate")
        self.take("(")
        source = self.pattern()
        self.take(";")
        var = self.take(kind="name")
        if not var.startswith("$"):
            raise NotPlain("accumulate result without a $variable")
        self.take(":")
        function = self.name()
        self.take("(")
        arg = self.take(kind="name") if self.peek()[1] != ")" else None
        self.take(")")
        constraints = []
        if self.peek()[1] == ";":
            self.take(";")
            while True:
                self.take(var)
                op = self.take(kind="punct")
                if op not in OPERATORS:
                    raise NotPlain(f"operator {op}")
                literal, text = self.literal()
                if "n" not in literal:
                    raise NotPlain("an accumulate result compared with a non-number")
                constraints.append({"op": op, "literal": literal, "text": f"{var} {op} {text}"})
                if self.peek()[1] != ",":
                    break
                self.take(",")
        self.take(")")
        return {"source": source, "function": function, "arg": arg, "var": var, "constraints": constraints}

    def from_accumulate(self, result: dict[str, Any]) -> dict[str, Any]:
        """``Number( intValue >= 2 ) from accumulate( Loan( … ), count( 1 ) )``: the result pattern
        (its type and constraints on ``intValue``/``longValue``/``doubleValue``), the source pattern
        and one function over a bound variable or a number."""
        self.take("from")
        self.take("accumulate")
        self.take("(")
        source = self.pattern()
        self.take(",")
        function = self.name()
        self.take("(")
        if self.peek()[1].startswith("$"):
            arg: dict[str, Any] = {"var": self.take(kind="name")}
        else:
            arg = self.literal()[0]
        self.take(")")
        self.take(")")
        if result["binds"] or any("literal" not in c or c["op"] not in OPERATORS for c in result["constraints"]):
            raise NotPlain("a result pattern with more than comparisons with numbers")
        return {"result": result, "source": source, "function": function, "arg": arg}

    def call(self) -> dict[str, Any]:
        target = self.name()
        if target.startswith("$"):
            raise NotPlain("a call on a bound variable")
        self.take(".")
        method = self.name()
        args = self.arguments()
        self.take(";")
        return {"target": target, "method": method, "args": args}

    def arguments(self) -> list[Any]:
        """``( a, b, … )``: a call's arguments, each read by :meth:`argument`."""
        self.take("(")
        args: list[Any] = []
        while self.peek()[1] != ")":
            if args:
                self.take(",")
            args.append(self.argument())
        self.take(")")
        return args

    def argument(self) -> dict[str, Any]:
        """A literal, a bound variable ``$v``, a getter ``$v.getX()``, or a text built with ``+`` from
        those that starts with a text literal (so every ``+`` is Java's string concatenation)."""
        terms = [self.term()]
        while self.peek()[1] == "+":
            self.take("+")
            terms.append(self.term())
        if len(terms) == 1:
            return terms[0]
        if "s" not in terms[0]:
            raise NotPlain("a + that is not a text concatenation")
        return {"concat": terms}

    def term(self) -> dict[str, Any]:
        kind, tok = self.peek()
        if kind == "name" and not tok.startswith("$") and tok not in ("true", "false"):
            return self.static_call()
        if not tok.startswith("$"):
            return self.literal(long_ok=True)[0]
        var = self.take(kind="name")
        if self.peek()[1] != ".":
            return {"var": var}
        self.take(".")
        getter = self.name()
        if not getter.startswith(("get", "is")):
            raise NotPlain("a method other than a getter on a bound variable")
        self.take("(")
        self.take(")")
        return {"var": var, "getter": getter}

    def static_call(self) -> dict[str, Any]:
        """``String.format( … )``, ``Math.max( $a.getAge(), 1L )``: a static method of a ``java.lang``
        class the rule policy allows, named by its simple name, with arguments of the same forms.
        The Java side resolves the method as javac does (widening, boxing, varargs, the most
        specific one) and refuses a name the rule's package or imports would shadow."""
        owner = self.name()
        if not owner[:1].isupper():
            raise NotPlain(f"a call on {owner}, not a class or a bound variable")
        if not _POLICY.allows_class(f"java.lang.{owner}"):
            raise NotPlain(f"a static call on {owner}, not a java.lang class the rule policy allows")
        self.take(".")
        method = self.name()
        if method in REFLECTION_MEMBERS:
            raise NotPlain(f"reflection ({owner}.{method})")
        args = self.arguments()
        if self.peek()[1] == ".":
            raise NotPlain("a call on the result of a call")
        return {"static": owner, "method": method, "args": args}
