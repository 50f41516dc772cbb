"""Mapping specs written as YAML text, with the line and column of every key.

Why: an author edits a mapping as YAML in the workbench, and a refused mapping names the bad key
as a path (``mapping.children.customers.link``, see :mod:`gateway.rdf.mapping`). Keeping the YAML
node tree lets that path point at its line and column in the author's own text, and a YAML syntax
error says where it is too.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import yaml


class SpecSyntaxError(ValueError):
    """Text that is not YAML (or not one object); ``line``/``column`` are 1-based."""

    def __init__(self, message: str, line: int = 0, column: int = 0) -> None:
        super().__init__(f"line {line}, column {column}: {message}" if line else message)
        self.message = message
        self.line = line
        self.column = column


@dataclass(frozen=True)
class SpecText:
    """A spec read from YAML text: its data and the node tree to locate key paths in."""

    spec: dict[str, Any]
    root: yaml.Node

    def locate(self, where: str) -> tuple[int, int]:
        """The 1-based (line, column) of the deepest key of ``where`` (``mapping.a.b``) in the text;
        (0, 0) when not even its first key is there."""
        node: yaml.Node | None = self.root
        found: yaml.Mark | None = None
        for part in where.split(".")[1:]:
            if not isinstance(node, yaml.MappingNode):
                break
            match = next(((k, v) for k, v in node.value if isinstance(k, yaml.ScalarNode) and k.value == part), None)
            if match is None:
                break
            found, node = match[0].start_mark, match[1]
        return (found.line + 1, found.column + 1) if found is not None else (0, 0)


def read_spec_text(text: str) -> SpecText:
    """Parse YAML ``text`` holding one mapping object; SpecSyntaxError with where it went wrong."""
    try:
        root = yaml.compose(text, Loader=yaml.SafeLoader)
        data = yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = (mark.line + 1, mark.column + 1) if mark is not None else (0, 0)
        raise SpecSyntaxError(f"not valid YAML: {exc.problem or exc.context}", *where) from None
    except yaml.YAMLError as exc:
        raise SpecSyntaxError(f"not valid YAML: {exc}") from None
    if not isinstance(data, dict) or root is None:
        raise SpecSyntaxError("a mapping must be an object (keys such as subject, type, fields)", 1, 1)
    return SpecText(spec=data, root=root)


def spec_to_text(spec: Any) -> str:
    """The YAML an author edits for a stored spec (keys in their stored order)."""
    return yaml.safe_dump(spec, sort_keys=False, allow_unicode=True, default_flow_style=False)
