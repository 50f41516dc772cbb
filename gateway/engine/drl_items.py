"""The top-level items of a DRL text (rules, queries, declared types, functions ...), where each one
stands exactly, and what a rule's compiled form depends on.

Why: an incremental build compiles a rule set's rules in units and reuses rules compiled before.
For that it needs, for every rule,

- its exact character range, to keep it in or blank it out of a unit's text; blanking keeps every
  other character where it was, so line and column of a compile error stay those of the author's
  file;
- a key that changes whenever its compiled form could: its own text, its file's header (package,
  imports, globals, attributes), the set's functions, queries, windows and entry points, and the
  declared types it names, with the types those name in turn.

Drools' own DRL parser finds the items (``Units.describe`` on its PackageDescr); their ranges are
refined here because the parser's offsets of a declaration start at its name and may end before or
after its closing ``end``. Texts whose items cannot be placed unambiguously are reported as such,
and the compiler then builds the rule set in one unit.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import re
from collections.abc import Callable, Container, Iterable
from dataclasses import dataclass, field

_IDENT = re.compile(r"[A-Za-z_$][\w$]*")
_END = re.compile(r"\bend\b")
_STRING_OR_COMMENT = re.compile(r'"(?:\\.|[^"\\\n])*"|\'(?:\\.|[^\'\\\n])*\'|//[^\n]*|#[^\n]*|/\*.*?\*/', re.DOTALL)
_KEYWORD = {"rule": "rule", "query": "query", "function": "function", "type": "declare", "enum": "declare",
            "window": "declare", "entrypoint": "declare"}
DECLARATION_KINDS = ("type", "enum")
CONTEXT_KINDS = ("query", "function", "window", "entrypoint")


@dataclass(frozen=True)
class Item:
    """One top-level item of a DRL text: ``text[start:end]`` is all of it."""

    kind: str  # rule, query, type, enum, function, window, entrypoint
    name: str
    start: int
    end: int
    line: int
    parent: str | None = None  # the rule a rule extends


@dataclass
class SourceItems:
    """A DRL text (written or expanded from a .dslr) split into its items."""

    file: str
    package: str
    text: str
    items: list[Item]
    unit: bool = False  # declares a rule unit (built in one piece)
    _header: str | None = field(default=None, repr=False)

    @property
    def rules(self) -> list[Item]:
        return [i for i in self.items if i.kind == "rule"]

    def item_text(self, item: Item) -> str:
        return self.text[item.start:item.end]

    def header(self) -> str:
        """What every item of this file sees (package, imports, globals, attributes), without the
        items, comments and layout: a rule's key includes it, so an edit elsewhere does not."""
        if self._header is None:
            kept = _cut(self.text, [(i.start, i.end) for i in self.items])
            self._header = " ".join(_strip_comments(kept).split())
        return self._header

    def only(self, apart: Container[tuple[str, int]]) -> bool:
        """Whether this file holds nothing but items of ``apart`` (queries built in plain units)
        and declares no global: the declarations unit needs nothing of it (explain's query files)."""
        return bool(self.items) and all((self.file, i.start) in apart for i in self.items) and not re.search(
            r"\bglobal\b", self.header())

    def blanked(self, keep: Callable[[Item], bool]) -> str:
        """The text with every item ``keep`` refuses replaced by spaces (line breaks kept)."""
        return blank(self.text, [(i.start, i.end) for i in self.items if not keep(i)])


def blank(text: str, ranges: Iterable[tuple[int, int]]) -> str:
    """``text`` with the characters of ``ranges`` turned into spaces, line breaks kept, so every
    other character keeps its line and column."""
    out: list[str] = []
    pos = 0
    for start, end in sorted(ranges):
        out.append(text[pos:start])
        out.append(re.sub(r"[^\n]", " ", text[start:end]))
        pos = end
    out.append(text[pos:])
    return "".join(out)


def _cut(text: str, ranges: Iterable[tuple[int, int]]) -> str:
    out, pos = [], 0
    for start, end in sorted(ranges):
        out.append(text[pos:start])
        pos = end
    out.append(text[pos:])
    return "\n".join(out)


def _strip_comments(text: str) -> str:
    return _STRING_OR_COMMENT.sub(lambda m: m.group(0) if m.group(0)[0] in "\"'" else " ", text)


def _code_mask(text: str) -> list[tuple[int, int]]:
    """Ranges of strings and comments (where keywords are not keywords)."""
    return [(m.start(), m.end()) for m in _STRING_OR_COMMENT.finditer(text)]


class _Masked:
    """Answers "is this offset inside a string or comment?" for one text."""

    def __init__(self, text: str):
        self.ranges = _code_mask(text)
        self.starts = [r[0] for r in self.ranges]

    def inside(self, pos: int) -> bool:
        from bisect import bisect_right

        k = bisect_right(self.starts, pos) - 1
        return k >= 0 and self.ranges[k][0] <= pos < self.ranges[k][1]


def parse_items(file: str, text: str, described: str) -> SourceItems | None:
    """The items of ``text`` from ``Units.describe``'s JSON, with refined ranges; None when they
    cannot be placed unambiguously (the caller then builds the whole set as one unit)."""
    info = json.loads(described)
    masked = _Masked(text)
    items: list[Item] = []
    for kind, name, start, end, line, parent in info["items"]:
        placed = _place(kind, text, int(start), int(end), masked)
        if placed is None:
            return None
        items.append(Item(kind, name, placed[0], placed[1], int(line), parent))
    items.sort(key=lambda i: i.start)
    for a, b in itertools.pairwise(items):
        if a.end > b.start:
            return None
    # a text without a package statement is in Drools' "defaultpkg"
    return SourceItems(file, info["package"] or "defaultpkg", text, items, unit=bool(info["unit"]))


def _place(kind: str, text: str, start: int, end: int, masked: _Masked) -> tuple[int, int] | None:
    keyword = _KEYWORD.get(kind)
    if keyword is None or start < 0 or end < 0:
        return None
    begin = _keyword_before(text, keyword, start, masked)
    if begin is None:
        return None
    if kind == "function":
        close = _closing_brace(text, begin, masked)
        return (begin, close) if close is not None else None
    stop = _end_token(text, max(begin, end - 4), masked)
    return (begin, stop) if stop is not None else None


def _keyword_before(text: str, keyword: str, start: int, masked: _Masked) -> int | None:
    """Where ``keyword`` opening the item at ``start`` begins (at ``start`` or just before it)."""
    if text.startswith(keyword, start) and not masked.inside(start):
        return start
    window_start = max(0, start - 400)
    found = None
    for m in re.finditer(r"\b" + keyword + r"\b", text[window_start:start + len(keyword)]):
        pos = window_start + m.start()
        if not masked.inside(pos):
            found = pos
    return found


def _end_token(text: str, search_from: int, masked: _Masked) -> int | None:
    """Just past the first ``end`` keyword at or after ``search_from`` (outside strings/comments)."""
    for m in _END.finditer(text, search_from):
        if not masked.inside(m.start()):
            return m.end()
    return None


def _closing_brace(text: str, begin: int, masked: _Masked) -> int | None:
    """Just past the brace closing the first ``{`` after ``begin`` (a function's body)."""
    depth = 0
    pos = text.find("{", begin)
    while 0 <= pos < len(text):
        ch = text[pos]
        if not masked.inside(pos):
            if ch == "{":
                depth += 1
            elif ch == "}":
                depth -= 1
                if depth == 0:
                    return pos + 1
        pos += 1
    return None


# --------------------------------------------------------------------------- dependencies and keys


def digest(*parts: str) -> str:
    h = hashlib.sha256()
    for part in parts:
        h.update(part.encode("utf-8", "surrogatepass"))
        h.update(b"\0")
    return h.hexdigest()[:32]


def identifiers(text: str) -> set[str]:
    return set(_IDENT.findall(_strip_comments(text)))


@dataclass
class RuleSetItems:
    """All files of a rule set, split, with the facts keys are made of."""

    sources: list[SourceItems]
    type_texts: dict[str, str] = field(default_factory=dict)  # declared type simple name -> its declaration(s)
    type_deps: dict[str, set[str]] = field(default_factory=dict)
    context_hash: str = ""  # functions, queries, windows, entry points of the whole set
    context_types: set[str] = field(default_factory=set)
    package_headers: dict[str, str] = field(default_factory=dict)  # package -> hash of its files' headers

    @classmethod
    def of(cls, sources: list[SourceItems]) -> RuleSetItems:
        out = cls(sources)
        for src in sources:
            for item in src.items:
                if item.kind in DECLARATION_KINDS:
                    simple = item.name.rsplit(".", 1)[-1]
                    out.type_texts[simple] = out.type_texts.get(simple, "") + "\n" + src.item_text(item)
        names = set(out.type_texts)
        for name, text in out.type_texts.items():
            out.type_deps[name] = (identifiers(text) & names) - {name}
        context_parts: list[str] = []
        for src in sorted(sources, key=lambda s: s.file):
            context_types = identifiers(src.header())
            for item in src.items:
                if item.kind in CONTEXT_KINDS:
                    text = src.item_text(item)
                    context_parts.append(f"{src.file}\0{item.kind}\0{text}")
                    context_types |= identifiers(text)
            out.context_types |= context_types & names
        out.context_hash = digest(*context_parts)
        headers: dict[str, list[str]] = {}
        for src in sorted(sources, key=lambda s: s.file):  # imports and globals are package-wide in DRL
            headers.setdefault(src.package, []).append(f"{src.file}\0{src.header()}")
        out.package_headers = {pkg: digest(*parts) for pkg, parts in headers.items()}
        return out

    def closure(self, names: set[str]) -> list[str]:
        """The declared types ``names`` name, directly or through the types they name (sorted)."""
        seen: set[str] = set()
        todo = [n for n in names if n in self.type_texts]
        while todo:
            name = todo.pop()
            if name in seen:
                continue
            seen.add(name)
            todo.extend(self.type_deps.get(name, ()))
        return sorted(seen)

    def types_hash(self, names: Iterable[str]) -> str:
        return digest(*(f"{n}\0{self.type_texts[n]}" for n in names))

    def rule_key(self, env: str, src: SourceItems, item: Item) -> str:
        """What a rule's compiled classes depend on, hashed: reuse them while it is unchanged."""
        text = src.item_text(item)
        used = (identifiers(text) & set(self.type_texts)) | self.context_types
        return digest("rule", env, src.file, src.package, src.header(), self.package_headers.get(src.package, ""),
                      self.context_hash, self.types_hash(self.closure(used)), text)

    def declarations_key(self, env: str, apart: Container[tuple[str, int]] = frozenset()) -> str:
        """What the declarations unit (types, functions, queries ... of every file) depends on;
        ``apart``: (file, start) of queries built in units of their own, not part of it."""
        parts = []
        for src in sorted(self.sources, key=lambda s: s.file):
            if src.only(apart):
                continue
            parts.append(f"{src.file}\0{src.package}\0{src.header()}")
            parts.extend(f"{i.kind}\0{src.item_text(i)}" for i in src.items
                         if i.kind != "rule" and (src.file, i.start) not in apart)
        return digest("declarations", env, *parts)
