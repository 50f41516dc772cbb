"""The rule policy: what an author's rules may name and call, checked before anything compiles.

Why: DRL is Java. A then-part, a ``function``, an ``eval``, an ``import`` or a ``from`` expression
can call anything the JVM can — files, processes, reflection, the network — and Java 17+ no longer
offers a security manager to stop it at run time. So the gateway decides *before* compiling: a
rule set deployed or tried by an ``author`` may only name

- the rule set's own declared types, globals, functions and bound variables (``$c``);
- ``insert``, ``insertLogical``, ``modify``, ``update``, ``retract``/``delete`` and read-only
  ``drools``/``kcontext`` calls (:data:`DROOLS_METHODS`);
- the classes and packages of :data:`DEFAULT_ALLOW` (``String``, boxed primitives, ``Math``,
  ``java.time``, ``java.util`` collections as values, the ``Actions`` global's class…) and of the
  deployment's ``engine.rule_policy.allow``.

A ``developer`` may deploy anything (the check does not run).

How: not a list of forbidden words. A small Java/DRL lexer (strings, chars, text blocks and
comments are skipped, so text inside them is never flagged) turns the *expanded* DRL of every file
into tokens; each name is then resolved the way the compiler resolves it: bound variables, locals
and globals are values; a capitalised simple name is a type (declared in the rule set, imported,
or implicitly ``java.lang``); a dotted name whose head is no variable is a qualified class name
(``java.nio.file.Files``). Every class named — in an ``import``, a ``global``, a declared field,
a pattern, a ``new``, a cast, a static call or a method reference — must be allowed. Receivers of
method calls are not typed here, so the members by which *any* value leads to reflection
(:data:`REFLECTION_MEMBERS`: ``getClass()``, ``.class``…) are refused on every receiver, and a
dotted name that could be read either as a variable's fields or as a package (``java.lang.X``) must
be allowed under both readings. Unqualified calls must be the rule set's functions, the DRL
built-ins, or (inside a pattern or a ``modify`` block) the fact's own methods.

A violation is a :class:`Violation` at the line and column of the name in the DRL text; the
compiler maps it to the author's file (a ``.dslr`` line, a decision table cell) like a compile error.
"""

from __future__ import annotations

import re
import unicodedata
from dataclasses import dataclass, field
from typing import Iterable

#: Classes (``a.b.C``) and packages (``a.b``, meaning the package and its subpackages) an author's
#: rules may name. Values only: nothing here reads or writes files, starts threads or processes,
#: opens sockets or reaches reflection.
DEFAULT_ALLOW: tuple[str, ...] = (
    # java.lang: text, numbers, maths, the exceptions a rule may throw
    "java.lang.String", "java.lang.StringBuilder", "java.lang.CharSequence", "java.lang.Character",
    "java.lang.Boolean", "java.lang.Byte", "java.lang.Short", "java.lang.Integer", "java.lang.Long",
    "java.lang.Float", "java.lang.Double", "java.lang.Number", "java.lang.Math", "java.lang.StrictMath",
    "java.lang.Object", "java.lang.Comparable", "java.lang.Iterable", "java.lang.Enum", "java.lang.Void",
    "java.lang.Exception", "java.lang.RuntimeException", "java.lang.IllegalArgumentException",
    "java.lang.IllegalStateException", "java.lang.ArithmeticException", "java.lang.NullPointerException",
    "java.lang.NumberFormatException", "java.lang.UnsupportedOperationException",
    "java.lang.IndexOutOfBoundsException",
    # numbers, time, collections, text matching as values
    "java.math", "java.time", "java.util.function", "java.util.stream", "java.util.regex",
    "java.util.List", "java.util.ArrayList", "java.util.LinkedList", "java.util.Map", "java.util.HashMap",
    "java.util.LinkedHashMap", "java.util.TreeMap", "java.util.SortedMap", "java.util.NavigableMap",
    "java.util.Set", "java.util.HashSet", "java.util.LinkedHashSet", "java.util.TreeSet", "java.util.SortedSet",
    "java.util.NavigableSet", "java.util.Collection", "java.util.Collections", "java.util.Arrays",
    "java.util.Objects", "java.util.Optional", "java.util.OptionalInt", "java.util.OptionalLong",
    "java.util.OptionalDouble", "java.util.Iterator", "java.util.ListIterator", "java.util.Queue",
    "java.util.Deque", "java.util.ArrayDeque", "java.util.PriorityQueue", "java.util.Comparator",
    "java.util.Date", "java.util.UUID", "java.util.Locale", "java.util.StringJoiner",
    "java.util.NoSuchElementException", "java.util.Random", "java.util.Calendar", "java.util.GregorianCalendar",
    "java.util.TimeZone", "java.util.Currency", "java.text",
    # what the gateway hands to rules: the actions global
    "org.printeps.gateway.Actions",
)

#: ``drools.<m>(…)`` / ``kcontext.<m>(…)`` an author may call: the built-ins and read-only calls.
DROOLS_METHODS = frozenset({
    "getRule", "getMatch", "getFactHandle", "getTuple", "insert", "insertLogical", "update", "modify",
    "delete", "retract", "halt",
})

#: Unqualified calls a then-part may make (the consequence built-ins).
BUILTIN_CALLS = frozenset({"insert", "insertLogical", "modify", "update", "retract", "delete"})

#: Words of the when-part (and of attributes) written like calls: ``eval(…)``, ``not(…)``,
#: ``accumulate(…; sum($x))``, ``over window:time(5m)``.
LHS_CALLS = frozenset({
    "eval", "not", "exists", "forall", "and", "or", "from", "collect", "accumulate", "acc", "groupby",
    "init", "action", "reverse", "result", "sum", "count", "min", "max", "average", "collectList",
    "collectSet", "countDistinct", "time", "length", "timer", "duration", "salience", "enabled",
    "if", "do", "break", "in", "notin", "int", "cron", "expr", "str", "over", "window",
})

#: Members by which any value reaches reflection (a ``Class``, a class loader, a method handle).
#: Refused on every receiver because receivers are not typed here.
REFLECTION_MEMBERS = frozenset({
    "class", "getClass", "getDeclaringClass", "getClassLoader", "getContextClassLoader", "forName",
    "getDeclaredMethod", "getDeclaredMethods", "getMethod", "getMethods", "getDeclaredField",
    "getDeclaredFields", "getField", "getFields", "getDeclaredConstructor", "getDeclaredConstructors",
    "getConstructor", "getConstructors", "newInstance", "setAccessible", "loadClass", "defineClass",
    "invoke", "invokeExact", "invokeWithArguments",
})

#: Package roots a rule set may not declare itself in (its simple names would resolve there).
RESERVED_PACKAGES = ("java", "javax", "jdk", "sun", "com.sun")

JAVA_KEYWORDS = frozenset({
    "abstract", "assert", "boolean", "break", "byte", "case", "catch", "char", "class", "const", "continue",
    "default", "do", "double", "else", "enum", "extends", "final", "finally", "float", "for", "goto", "if",
    "implements", "import", "instanceof", "int", "interface", "long", "native", "new", "package", "private",
    "protected", "public", "return", "short", "static", "strictfp", "super", "switch", "synchronized",
    "this", "throw", "throws", "transient", "try", "void", "volatile", "while", "true", "false", "null", "var",
    "yield", "record", "sealed", "permits",
})

# java.lang's public classes, to name an unimported capitalised name in a refusal ("java.lang.Runtime")
_JAVA_LANG = frozenset({
    "System", "Runtime", "Thread", "ThreadGroup", "ThreadLocal", "InheritableThreadLocal", "Process",
    "ProcessBuilder", "ProcessHandle", "Class", "ClassLoader", "ClassValue", "Module", "ModuleLayer",
    "Package", "SecurityManager", "StackWalker", "Compiler", "reflect", "invoke", "ref",
    *(c.rsplit(".", 1)[1] for c in DEFAULT_ALLOW if c.startswith("java.lang.")),
})

_TOKEN = re.compile(r'''
    (?P<ws>[ \t\r\f]+|\n)
  | (?P<comment>//[^\n]*|\#[^\n]*|/\*.*?(?:\*/|\Z))
  | (?P<str>"""[ \t\f]*\r?\n(?:\\.|[^\\])*?(?:"""|\Z)|"(?:\\.|[^"\\\n])*"?|'(?:\\.|[^'\\\n])*'?)
  | (?P<num>\d[\w]*(?:\.\d[\w]*)?(?:[eE][+-]?\d\w*)?)
  | (?P<id>(?:[^\W\d]|\$)(?:\w|\$)*)
  | (?P<op>->|::|==|!=|<=|>=|&&|\|\||:=|\S)
''', re.VERBOSE | re.DOTALL)


@dataclass(frozen=True)
class Token:
    kind: str  # id, num, str, op
    text: str
    line: int
    column: int


_UNICODE_ESCAPE = re.compile(r"(?<!\\)((?:\\\\)*)\\u+([0-9a-fA-F]{4})")
_CONTROL_IGNORABLE = re.compile("[\x00-\x08\x0e-\x1b\x7f-\x9f]")
_NON_ASCII = re.compile(r"[^\x00-\x7f]+")


def _java_text(text: str) -> str:
    """The text as javac reads it: ``\\uXXXX`` escapes translated first (so ``"\\u0022`` closes a
    string, as it does for the compiler), then the characters Java ignores inside identifiers
    removed (``Character.isIdentifierIgnorable``: ``Sys<U+200B>tem`` *is* ``System`` to javac)."""
    if "\\u" in text:
        text = _UNICODE_ESCAPE.sub(lambda m: m.group(1) + chr(int(m.group(2), 16)), text)
    text = _CONTROL_IGNORABLE.sub("", text)
    if not text.isascii():
        text = _NON_ASCII.sub(lambda m: "".join(c for c in m.group() if unicodedata.category(c) != "Cf"), text)
    return text


def tokenize(text: str) -> list[Token]:
    """The tokens of a DRL/Java text: identifiers, numbers, strings and operators with their 1-based
    line and column; whitespace and comments dropped (``//``, ``/* */`` and DRL's ``#``). The text
    is read as javac reads it (:func:`_java_text`)."""
    text = _java_text(text)
    out: list[Token] = []
    line, line_start = 1, 0
    for match in _TOKEN.finditer(text):
        kind = match.lastgroup or "op"
        value = match.group()
        if kind not in ("ws", "comment"):
            out.append(Token(kind, value, line, match.start() - line_start + 1))
        breaks = value.count("\n")
        if breaks:
            line += breaks
            line_start = match.start() + value.rfind("\n") + 1
    return out


@dataclass(frozen=True)
class Violation:
    """One thing the policy refuses, at a line and column of the DRL text."""

    line: int
    column: int
    name: str  # the class, call or member refused
    message: str


@dataclass
class RulePolicy:
    """The allowed classes and packages (:data:`DEFAULT_ALLOW` plus a deployment's ``extra``)."""

    extra: tuple[str, ...] = ()
    classes: frozenset[str] = field(init=False)
    packages: tuple[str, ...] = field(init=False)

    def __post_init__(self) -> None:
        entries = [e.strip().removesuffix(".*") for e in (*DEFAULT_ALLOW, *self.extra) if e and e.strip()]
        self.classes = frozenset(e for e in entries if _is_class_name(e))
        self.packages = tuple(e for e in entries if not _is_class_name(e))

    def allows_class(self, qualified: str) -> bool:
        """``a.b.C`` (or a nested ``a.b.C.D``) is in an allowed package or is an allowed class."""
        if qualified in self.classes or any(qualified.startswith(c + ".") for c in self.classes):
            return True
        package = _package_of(qualified)
        return any(package == p or package.startswith(p + ".") for p in self.packages)

    def allows_package(self, package: str) -> bool:
        return any(package == p or package.startswith(p + ".") for p in self.packages)

    def check(self, sources: Iterable[tuple[str, str]]) -> dict[str, list[Violation]]:
        """The violations of each DRL text of one rule set (``[(file, drl)]``; declared types,
        globals and functions of every file count for all of them): ``{file: [Violation]}``."""
        texts = [(fname, tokenize(drl)) for fname, drl in sources]
        known = _Known()
        for _, tokens in texts:
            known.collect(tokens)
        return {fname: _FileChecker(self, known, tokens).run() for fname, tokens in texts}


def applies_to(role: str | None) -> bool:
    """Whether the policy checks what ``role`` deploys or tries: every role but ``developer``;
    ``None`` is the gateway itself (seeds, followers replaying stored versions, local commands)."""
    return role is not None and role != "developer"


def _is_class_name(entry: str) -> bool:
    return entry.rsplit(".", 1)[-1][:1].isupper()


def _package_of(qualified: str) -> str:
    parts = qualified.split(".")
    for i, part in enumerate(parts):
        if part[:1].isupper():
            return ".".join(parts[:i])
    return ".".join(parts[:-1])


class _Known:
    """What the rule set itself declares, over all its files: types (simple and qualified names),
    their fields and functions (a global is a variable: its name needs no knowing)."""

    def __init__(self) -> None:
        self.types: set[str] = set()  # simple names, any package (to tell patterns)
        self.declared: set[tuple[str, str]] = set()  # (package, simple name): what a simple name resolves to
        self.qualified: set[str] = set()
        self.fields: set[str] = set()
        self.functions: set[str] = set()

    def collect(self, tokens: list[Token]) -> None:
        package = ""
        depth = 0
        i = 0
        while i < len(tokens):
            tok = tokens[i]
            if tok.text in "({[":
                depth += 1
            elif tok.text in ")}]":
                depth = max(0, depth - 1)
            elif tok.kind == "id" and depth == 0 and _at_item_start(tokens, i):
                if tok.text == "package":
                    package = ".".join(_dotted(tokens, i + 1)[0])
                elif tok.text == "declare":
                    j = i + 1
                    while j < len(tokens) and tokens[j].text in ("enum", "trait", "type", "window", "entry"):
                        j += 1
                    names, _ = _dotted(tokens, j)
                    if names:
                        self.types.add(names[-1])
                        self.declared.add((package, names[-1]) if len(names) == 1 else
                                          (".".join(names[:-1]), names[-1]))
                        self.qualified.add(".".join(names) if len(names) > 1 else f"{package}.{names[0]}".lstrip("."))
                    self.fields.update(_declared_fields(tokens, j))
                elif tok.text == "function":
                    j = _skip_type(tokens, i + 1)
                    if j < len(tokens) and tokens[j].kind == "id":
                        self.functions.add(tokens[j].text)
                    while j < len(tokens) and tokens[j].text != "{":
                        j += 1
                    i = _matching(tokens, j) if j < len(tokens) else j  # a body declares nothing
                elif tok.text in ("rule", "query"):
                    if tok.text == "query" and i + 1 < len(tokens):  # called from when-parts like a function
                        self.functions.add(tokens[i + 1].text.strip("\"'"))
                    while i + 1 < len(tokens) and not (tokens[i + 1].text == "end" and tokens[i + 1].kind == "id"):
                        i += 1  # nothing inside a rule declares a type, a global or a function
            i += 1


_ITEM_WORDS = frozenset({"package", "import", "global", "declare", "function", "rule", "query"})


def _at_item_start(tokens: list[Token], i: int) -> bool:
    """A DRL keyword starts a top-level item (not ``end`` of a rule text nor a field named so)."""
    return i == 0 or tokens[i - 1].text in (";", "end", "}") or tokens[i - 1].line < tokens[i].line


def _dotted(tokens: list[Token], i: int) -> tuple[list[str], int]:
    """The identifiers of ``a.b.c`` starting at ``i`` and the index after them."""
    names: list[str] = []
    while i < len(tokens) and tokens[i].kind == "id":
        names.append(tokens[i].text)
        if i + 2 < len(tokens) and tokens[i + 1].text == "." and tokens[i + 2].kind == "id":
            i += 2
        else:
            i += 1
            break
    return names, i


def _skip_type(tokens: list[Token], i: int) -> int:
    """The index after a type written at ``i`` (``a.b.C<D, E[]>[]``)."""
    _, i = _dotted(tokens, i)
    if i < len(tokens) and tokens[i].text == "<":
        depth = 0
        while i < len(tokens):
            depth += {"<": 1, ">": -1}.get(tokens[i].text, 0)
            i += 1
            if depth == 0:
                break
    while i + 1 < len(tokens) and tokens[i].text == "[" and tokens[i + 1].text == "]":
        i += 2
    return i


def _declared_fields(tokens: list[Token], i: int) -> set[str]:
    """The field names of the ``declare`` block starting at ``i``: ``name : Type`` up to ``end``."""
    found: set[str] = set()
    depth = 0
    while i < len(tokens) and not (tokens[i].text == "end" and depth == 0):
        depth += {"(": 1, ")": -1}.get(tokens[i].text, 0)
        if depth == 0 and tokens[i].kind == "id" and i + 1 < len(tokens) and tokens[i + 1].text == ":":
            found.add(tokens[i].text)
        i += 1
    return found


class _FileChecker:
    """Walks one file's tokens: the header items, then each rule, query, function and declaration."""

    def __init__(self, policy: RulePolicy, known: _Known, tokens: list[Token]) -> None:
        self.policy = policy
        self.known = known
        self.tokens = tokens
        self.package = ""
        self.imports: dict[str, str] = {}  # simple name -> qualified name (allowed or not)
        self.static_imports: set[str] = set()
        self.static_star = False  # an allowed class's static members, imported by ``import static a.B.*``
        self.found: list[Violation] = []
        self._seen: set[tuple[int, int]] = set()

    # ---- reporting ------------------------------------------------------------------------------
    def refuse(self, tok: Token, name: str, message: str) -> None:
        if (tok.line, tok.column) not in self._seen:
            self._seen.add((tok.line, tok.column))
            self.found.append(Violation(tok.line, tok.column, name, message))

    def refuse_class(self, tok: Token, qualified: str, used_as: str) -> None:
        how = f" (in '{used_as}')" if used_as and used_as != qualified else ""
        self.refuse(tok, qualified, f"rule policy: class '{qualified}'{how} is not allowed for an author: "
                                    "rules may use the rule set's declared types and globals and the allowed "
                                    "classes (engine.rule_policy.allow); a developer may deploy it")

    # ---- the file -------------------------------------------------------------------------------
    def run(self) -> list[Violation]:
        toks = self.tokens
        i = 0
        while i < len(toks):
            tok = toks[i]
            word = tok.text if tok.kind == "id" else ""
            if word == "package":
                names, i = _dotted(toks, i + 1)
                package = self.package = ".".join(names)
                if any(package == r or package.startswith(r + ".") for r in RESERVED_PACKAGES):
                    self.refuse(tok, package, f"rule policy: a rule set may not declare itself in package "
                                              f"'{package}' (its names would resolve to the JDK's classes)")
            elif word == "import":
                i = self.import_(i + 1)
            elif word == "global":
                j = _skip_type(toks, i + 1)
                self.code(i + 1, j, mode="type")
                i = j
            elif word == "declare":
                i = self.declare(i + 1)
            elif word in ("function", "rule", "query"):
                i = self.block(i, word)
            elif tok.text in (";", "end"):
                i += 1
            else:  # anything else (a top-level attribute, a stray word): names in it are checked like code
                j = i + 1
                while j < len(toks) and not (toks[j].kind == "id" and toks[j].text in _ITEM_WORDS):
                    j += 1
                self.code(i, j, mode="java")
                i = j
        return self.found

    def import_(self, i: int) -> int:
        toks = self.tokens
        kind = ""
        if i < len(toks) and toks[i].text in ("static", "function", "accumulate"):
            kind, i = toks[i].text, i + 1
        start = toks[i] if i < len(toks) else None
        names, i = _dotted(toks, i)
        star = i + 1 < len(toks) and toks[i].text == "." and toks[i + 1].text == "*"
        if star:
            i += 2
        if start is None or not names:
            return i
        qualified = ".".join(names)
        if kind in ("static", "function"):
            owner = qualified if star else ".".join(names[:-1])
            if not star:
                self.static_imports.add(names[-1])
            if not self._allowed(owner):
                self.refuse_class(start, owner, qualified + (".*" if star else ""))
            elif star:
                self.static_star = True
        elif kind == "accumulate":
            if not self._allowed(qualified):
                self.refuse_class(start, qualified, "")
            if i < len(toks) and toks[i].kind == "id":
                self.static_imports.add(toks[i].text)
                i += 1
        elif star:
            if not self.policy.allows_package(qualified):
                self.refuse(start, qualified + ".*", f"rule policy: importing package '{qualified}.*' is not "
                                                     "allowed for an author (import the allowed classes one by one)")
        else:
            self.imports[names[-1]] = qualified
            if not self._allowed(qualified):
                self.refuse_class(start, qualified, "")
        return i

    def declare(self, i: int) -> int:
        """``declare [enum] Name [extends X] @annotations fields end``: the types named in it, and
        any default value or enum argument as code."""
        toks = self.tokens
        enum = i < len(toks) and toks[i].text == "enum"
        while i < len(toks) and toks[i].text in ("enum", "trait", "type", "window", "entry", "-", "point"):
            i += 1
        _, i = _dotted(toks, i)  # the declared name itself
        end = i
        depth = 0
        while end < len(toks) and not (toks[end].text == "end" and depth == 0):
            depth += {"(": 1, ")": -1, "{": 1, "}": -1}.get(toks[end].text, 0)
            end += 1
        if enum:  # constants RED("r"), GREEN; come first: check only their arguments
            j = i
            while j < end and toks[j].text != ";":
                if toks[j].text == "(":
                    close = _matching(toks, j)
                    self.code(j + 1, close, mode="java")
                    j = close
                j += 1
            i = j
        self.code(i, end, mode="declare")
        return end + 1

    def block(self, i: int, word: str) -> int:
        """A function, rule or query: from its keyword to its end."""
        toks = self.tokens
        if word == "function":
            j = i + 1
            while j < len(toks) and toks[j].text != "{":
                j += 1
            close = _matching(toks, j) if j < len(toks) else len(toks) - 1
            self.code(i + 1, j, mode="type_params")  # return and parameter types
            self.code(j, close + 1, mode="java")
            return close + 1
        end = i + 1
        while end < len(toks) and not (toks[end].text == "end" and toks[end].kind == "id"):
            end += 1
        then = next((k for k in range(i + 1, end) if toks[k].text == "then" and toks[k].kind == "id"), end)
        self.code(i + 2, then, mode="lhs")  # after the rule's or query's name
        if then < end:
            self.code(then + 1, end, mode="java")
        return end + 1

    # ---- names in code --------------------------------------------------------------------------
    def _allowed(self, qualified: str) -> bool:
        return qualified in self.known.qualified or self.policy.allows_class(qualified)

    def code(self, start: int, end: int, mode: str) -> None:
        """Checks every name of ``tokens[start:end]``; ``mode``: "lhs" (patterns and constraints),
        "java" (then-parts, function bodies), "declare", "type" (a global's type) or
        "type_params" (a function's signature)."""
        toks = self.tokens
        stack: list[str] = []  # the open brackets: "pattern", "modify", "(", "{", "["
        i = start
        while i < end:
            tok = toks[i]
            if tok.text in ("(", "{", "["):
                stack.append(self._opening(i, start, mode))
                i += 1
                continue
            if tok.text in (")", "}", "]"):
                if stack:
                    stack.pop()
                i += 1
                continue
            prev = toks[i - 1].text if i > start else ""
            if tok.kind != "id" or prev == "@":
                i += 1
                continue
            if prev in (".", "::"):  # a member of what came before (a call's result, a value)
                if tok.text in REFLECTION_MEMBERS:
                    self.refuse(tok, tok.text, f"rule policy: reflection ('{tok.text}') is not allowed for an author")
                i += 1
                continue
            i = self.chain(i, end, mode, stack)

    def _opening(self, i: int, start: int, mode: str) -> str:
        toks = self.tokens
        prev = toks[i - 1] if i > start else None
        if toks[i].text == "(" and mode == "lhs" and prev is not None and prev.kind == "id" \
                and (prev.text[:1].isupper() or prev.text in self.known.types) \
                and (i < 2 or toks[i - 2].text != "new"):
            return "pattern"
        if toks[i].text == "{" and prev is not None and prev.text == ")":
            k = _matching_back(toks, i - 1, start)
            if k > start and toks[k - 1].text in ("modify", "with"):
                return "modify"
        return toks[i].text

    def chain(self, i: int, end: int, mode: str, stack: list[str]) -> int:
        """Resolves the name starting at ``tokens[i]`` (``a``, ``a.b.C.m``) the way the compiler
        does; returns the index after it."""
        toks = self.tokens
        names, after = _dotted(toks, i)
        after = min(after, end)
        names = names[: max(1, (after - i + 1) // 2)]
        before = len(self.found)
        end_of_name = self.resolve(i, names, after, end, mode, stack)
        if len(self.found) == before:  # the name itself is allowed: then what it reaches must be
            for n, name in enumerate(names[1:], start=1):
                if name in REFLECTION_MEMBERS:
                    self.refuse(toks[i + 2 * n], name,
                                f"rule policy: reflection ('{'.'.join(names)}') is not allowed for an author")
                    break
        return end_of_name

    def resolve(self, i: int, names: list[str], after: int, end: int, mode: str, stack: list[str]) -> int:
        toks = self.tokens
        head = names[0]
        call = after < end and toks[after].text == "("
        text = ".".join(names)
        in_fact = "pattern" in stack or "modify" in stack
        if head in JAVA_KEYWORDS and head not in ("this", "super"):
            return i + 1
        if head.startswith("$") or head in ("this", "super"):
            return after  # a value: its members are checked by chain()
        if head in ("drools", "kcontext"):
            if len(names) > 1 and names[1] not in DROOLS_METHODS:
                self.refuse(toks[i + 2], f"{head}.{names[1]}",
                            f"rule policy: '{head}.{names[1]}' is not allowed for an author (only "
                            f"{', '.join(sorted(DROOLS_METHODS))})")
            return after
        if len(names) == 1 and call and not head[:1].isupper():
            self.unqualified_call(i, mode, in_fact)
            return after
        if mode == "declare" and len(names) == 1 and after < end and toks[after].text == ":":
            return after  # a field's name
        first_type = next((n for n, name in enumerate(names) if name[:1].isupper()), None)
        if first_type is None:
            return after  # a variable, a field, a DRL word: no class is named
        if first_type == 0:
            if head in self.known.fields and in_fact:
                return after  # a capitalised field of the fact
            self.simple_type(toks[i], head, text)
            return after
        # a.b.C...: a qualified class name, unless the head is a variable; both readings must be allowed
        qualified = ".".join(names[: first_type + 1])
        if not self._allowed(qualified):
            self.refuse_class(toks[i], qualified, text)
        return after

    def simple_type(self, tok: Token, name: str, used_as: str) -> None:
        """A capitalised simple name: a declared type, an import, a static import, or java.lang."""
        if (self.package, name) in self.known.declared or name in self.static_imports:
            return
        qualified = self.imports.get(name)
        if qualified is not None:
            if not self._allowed(qualified):
                self.refuse_class(tok, qualified, used_as)
            return
        implicit = f"java.lang.{name}"
        if self.policy.allows_class(implicit):
            return
        if name in _JAVA_LANG:
            self.refuse_class(tok, implicit, used_as)
        else:
            self.refuse(tok, name, f"rule policy: '{name}' is not a type the rule set declares, imports or "
                                   "may use (engine.rule_policy.allow)")

    def unqualified_call(self, i: int, mode: str, in_fact: bool) -> None:
        tok = self.tokens[i]
        name = tok.text
        if name in REFLECTION_MEMBERS:
            self.refuse(tok, name, f"rule policy: reflection ('{name}') is not allowed for an author")
        elif name in self.known.functions or name in self.static_imports or name in BUILTIN_CALLS or in_fact:
            return
        elif self.static_star:  # a member of an allowed class (or of nothing: then it does not compile)
            return
        elif mode in ("lhs", "declare") and name in LHS_CALLS:
            return
        elif mode in ("java", "type_params") and self._declares_method(i):
            return
        else:
            self.refuse(tok, name, f"rule policy: call of '{name}(…)' is not allowed for an author: not a "
                                   "function of the rule set, a global's method or insert/modify/update/delete")

    def _declares_method(self, i: int) -> bool:
        """``int compare(A a, B b) {`` (in an anonymous class): a declaration, not a call."""
        toks = self.tokens
        prev = toks[i - 1] if i > 0 else None
        if prev is None or not (prev.text in (">", "]") or prev.kind == "id" and (
                prev.text not in JAVA_KEYWORDS or prev.text in _TYPE_WORDS)):
            return False
        close = _matching(toks, i + 1)
        return close + 1 < len(toks) and toks[close + 1].text in ("{", "throws")


_TYPE_WORDS = frozenset({"boolean", "byte", "char", "double", "float", "int", "long", "short", "void"})


def _matching(tokens: list[Token], i: int) -> int:
    """The index of the bracket closing the one at ``i`` (the last token if unclosed)."""
    pairs = {"(": ")", "{": "}", "[": "]"}
    want = pairs.get(tokens[i].text)
    depth = 0
    for k in range(i, len(tokens)):
        if tokens[k].text == tokens[i].text:
            depth += 1
        elif tokens[k].text == want:
            depth -= 1
            if depth == 0:
                return k
    return len(tokens) - 1


def _matching_back(tokens: list[Token], i: int, start: int) -> int:
    """The index of the ``(`` opening the ``)`` at ``i``."""
    depth = 0
    for k in range(i, start - 1, -1):
        if tokens[k].text == ")":
            depth += 1
        elif tokens[k].text == "(":
            depth -= 1
            if depth == 0:
                return k
    return start
