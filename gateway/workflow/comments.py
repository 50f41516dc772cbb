"""Keeping a workflow's comments when the visual editor writes its YAML again.

Why: the visual editor edits the parsed document, and PyYAML writes no comments, so every visual
save used to drop what the author had explained between the lines. Here each comment of the
previous text is tied to the line it stands on or above, named by its place in the document
(``processes/see_off/steps/#thank/with``: keys by name, steps by their ``id``, other list items by
position), and put back on or above the line with the same place in the new text. A comment
whose line is gone (its step was removed) goes with it.

The lines are read as block YAML the way people and :mod:`gateway.workflow.render` write it (one
key or list item a line, flow mappings only on one line); a line it cannot place keeps no
comment rather than a wrong one.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Iterator

_KEY = re.compile(r"""^(?P<key>"(?:[^"\\]|\\.)*"|'(?:[^']|'')*'|[^\s#'"{\[\]}:,][^:#]*?):(?:\s|$)""")
_STEP_ID = re.compile(r"""^id:\s*(?P<id>[A-Za-z_][A-Za-z0-9_]*)\s*$""")  # the comment is split off first


@dataclass
class Place:
    """One data line: where it is in the document, its indent, and its text without a trailing comment."""

    path: str
    indent: int
    body: str
    comment: str  # the trailing comment ("# ..."), or ""


@dataclass
class _Walker:
    """Follows block YAML line by line and names the place of each data line."""

    stack: list[tuple[int, str]] = field(default_factory=list)  # (indent, path segment)
    items: dict[str, int] = field(default_factory=dict)         # list items seen under a path

    def _parent(self, indent: int) -> str:
        while self.stack and self.stack[-1][0] >= indent:
            self.stack.pop()
        return "/".join(seg for _, seg in self.stack)

    def place(self, line: str) -> Place | None:
        body, comment = split_comment(line)
        if not body.strip():
            return None
        indent = len(body) - len(body.lstrip(" "))
        text = body.strip()
        if text.startswith("- ") or text == "-":
            parent = self._parent(indent)
            rest = text[1:].strip()
            step = _STEP_ID.match(rest)
            if step:
                segment = f"#{step.group('id')}"
            else:
                n = self.items.get(parent, 0)
                self.items[parent] = n + 1
                segment = f"[{n}]"
            self.stack.append((indent, segment))
            key = _KEY.match(rest)
            if key:  # "- key: value": the item's first key, one level in
                self.stack.append((indent + 2, _unquote(key.group("key"))))
            return Place("/".join(seg for _, seg in self.stack), indent, body, comment)
        key = _KEY.match(text)
        if key is None:
            return None  # a continuation line (a long scalar, a block text): no place of its own
        parent = self._parent(indent)
        name = _unquote(key.group("key"))
        self.stack.append((indent, name))
        return Place(f"{parent}/{name}" if parent else name, indent, body, comment)


def _unquote(key: str) -> str:
    key = key.strip()
    if len(key) >= 2 and key[0] == key[-1] and key[0] in "'\"":
        return key[1:-1]
    return key


def split_comment(line: str) -> tuple[str, str]:
    """(the line without its trailing comment, the comment) — a ``#`` inside quotes is text."""
    quote = ""
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or line[i - 1] in " \t"):
            return line[:i].rstrip(), line[i:].rstrip()
    return line.rstrip(), ""


_BLOCK_SCALAR = re.compile(r"(?:^|[:\s-])[|>][-+0-9]*$")  # "text: |", "- >-": a block of text follows


def places(text: str) -> Iterator[tuple[int, Place | None, bool]]:
    """(line number, its place or None, whether it is a comment line) for every line of ``text``.
    The lines of a block scalar (``text: |``) are text, even when they start with ``#``."""
    walker = _Walker()
    block_of: int | None = None  # the indent of the line that opened a block scalar
    for number, line in enumerate(text.splitlines()):
        stripped = line.strip()
        indent = len(line) - len(line.lstrip(" "))
        if block_of is not None and (not stripped or indent > block_of):
            yield number, None, False
            continue
        block_of = None
        if not stripped or stripped.startswith("#"):
            yield number, None, bool(stripped)
            continue
        place = walker.place(line)
        if place is not None and _BLOCK_SCALAR.search(place.body):
            block_of = place.indent
        yield number, place, False


def comments_by_place(text: str) -> tuple[dict[str, list[str]], dict[str, str]]:
    """The comment blocks above data lines and the trailing comments of data lines, by place.
    The block above the first data line is not included (the renderer keeps it as the header)."""
    lines = text.splitlines()
    above: dict[str, list[str]] = {}
    trailing: dict[str, str] = {}
    pending: list[str] = []
    seen_data = False
    for number, place, is_comment in places(text):
        stripped = lines[number].strip()
        if place is None:
            if is_comment:
                pending.append(stripped)
            elif not stripped and pending:
                pending.append("")
            continue
        if seen_data and pending:
            while pending and not pending[-1]:
                pending.pop()
            above.setdefault(place.path, pending)
        pending = []
        seen_data = True
        if place.comment:
            trailing.setdefault(place.path, place.comment)
    return above, trailing


def restore(new_text: str, previous_text: str) -> str:
    """``new_text`` with the comments of ``previous_text`` put back at the same places."""
    above, trailing = comments_by_place(previous_text)
    if not above and not trailing:
        return new_text
    lines = new_text.splitlines()
    out: list[str] = []
    for number, place, _ in places(new_text):
        line = lines[number]
        if place is not None:
            for comment in above.pop(place.path, []):
                out.append(" " * place.indent + comment if comment else "")
            note = trailing.pop(place.path, "")
            if note and not place.comment:
                line = f"{place.body}  {note}"
        out.append(line)
    return "\n".join(out) + ("\n" if new_text.endswith("\n") else "")
