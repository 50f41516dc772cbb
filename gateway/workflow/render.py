"""Writing a workflow document (the parsed YAML, as the visual editor changes it) back to YAML.

Why: YAML stays the storage format, and the visual editor edits the document as data. What it
writes should look like what a person writes, so the YAML tab and the version diffs stay readable:
keys in the document's order, small leaf mappings and lists in flow style on one line
(``say: {kind: ros_service, ...}``, ``with: {text: ...}``), steps and processes in block style,
the leading comment block of the previous text kept as the header, and its other comments put
back where they stood (:mod:`gateway.workflow.comments`).
"""

from __future__ import annotations

from typing import Any

import yaml

from gateway.workflow.comments import restore

FLOW_WIDTH = 110  # a leaf mapping longer than this on one line is written as a block


class _Dumper(yaml.SafeDumper):
    """SafeDumper that indents lists under their key, as the hand-written workflows do."""

    def increase_indent(self, flow: bool = False, indentless: bool = False) -> bool:
        return super().increase_indent(flow, False)


def _depth(value: Any) -> int:
    if isinstance(value, dict):
        return 1 + max((_depth(v) for v in value.values()), default=0)
    if isinstance(value, list):
        return 1 + max((_depth(v) for v in value), default=0)
    return 0


def _is_leaf(value: Any) -> bool:
    """Small enough to read on one line: at most two levels deep (``[{table: t1, cups: 2}]``)."""
    return _depth(value) <= 2


def _one_line(value: Any) -> str:
    return yaml.safe_dump(value, default_flow_style=True, sort_keys=False, width=10_000, allow_unicode=True).strip()


def _represent_dict(dumper: yaml.SafeDumper, value: dict[str, Any]) -> yaml.Node:
    flow = bool(value) and _is_leaf(value) and not _is_step(value) and len(_one_line(value)) <= FLOW_WIDTH
    return dumper.represent_mapping("tag:yaml.org,2002:map", value.items(), flow_style=flow)


def _represent_list(dumper: yaml.SafeDumper, value: list[Any]) -> yaml.Node:
    flow = _is_leaf(value) and not any(_is_step(v) for v in value) and len(_one_line(value)) <= FLOW_WIDTH
    return dumper.represent_sequence("tag:yaml.org,2002:seq", value, flow_style=flow)


def _is_step(value: Any) -> bool:
    """Steps are always blocks (one key a line), however small: they are what people read."""
    return isinstance(value, dict) and any(k in value for k in ("module", "process", "if", "set"))


class _Block(dict):
    """The document itself: always a block, whatever its size."""


_Dumper.add_representer(_Block, lambda dumper, value: dumper.represent_mapping(
    "tag:yaml.org,2002:map", value.items(), flow_style=False))
_Dumper.add_representer(dict, _represent_dict)
_Dumper.add_representer(list, _represent_list)


def leading_comments(text: str) -> str:
    """The comment lines (and blank lines) before the first line of data."""
    kept: list[str] = []
    for line in text.splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            break
        kept.append(line)
    while kept and not kept[-1].strip():
        kept.pop()
    return "\n".join(kept) + "\n" if kept else ""


def to_yaml(document: dict[str, Any], previous_text: str = "") -> str:
    """``document`` as workflow YAML, under the leading comments of ``previous_text``."""
    body = yaml.dump(_Block(document), Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=FLOW_WIDTH,
                     default_flow_style=False)
    return leading_comments(previous_text) + restore(body, previous_text)


def read_document(text: str) -> dict[str, Any] | None:
    """The document of a YAML text when it is a mapping that parses, else None (the loader says why)."""
    try:
        data = yaml.safe_load(text)
    except (yaml.YAMLError, RecursionError):
        return None
    return data if isinstance(data, dict) else None
