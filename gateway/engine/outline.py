"""A rule set as a list of what its rules do: each rule's name, its sentences in the owner's words,
and where it stands — so an owner finds "Greet a pair" without reading a 400-line file.

Why here and not in the browser: the same reading serves the workbench's rule list, a search over
it and any REST client, and decision tables are read by the engine's own table reader. Plain text
work only (no compiling): a draft with errors still has an outline.

* ``.dslr`` — each ``rule "…"``: its when-sentences and then-sentences as written (comments,
  attributes such as ``salience`` and the keywords left out).
* ``.drl`` — each rule with its line; its conditions and actions as code lines (technical).
* decision tables — each row that makes a rule: the row's cells, labelled with the table's column
  labels (``Kind: pair · Says: Welcome. Two seats?``), and its row number.
"""

from __future__ import annotations

import re
from typing import Any

from gateway.engine import decision_table
from gateway.engine.ruleset import is_table_file

RULE_LINE = re.compile(r'^\s*rule\s+(?:"((?:[^"\\]|\\.)*)"|(\S+))')
ATTRIBUTE = re.compile(r"^(salience|no-loop|lock-on-active|agenda-group|activation-group|ruleflow-group|"
                       r"date-effective|date-expires|enabled|dialect|duration|timer|calendars|auto-focus)\b")


def outline(files: dict[str, str]) -> list[dict[str, Any]]:
    """Every rule of the rule set's rule files, file by file: ``{"name", "file", "line" (or "row"
    for a table), "when": [sentences], "then": [sentences]}``."""
    out: list[dict[str, Any]] = []
    for name in sorted(files):
        lower = name.lower()
        if lower.endswith((".dslr", ".drl")):
            out.extend(_text_rules(name, files[name]))
        elif is_table_file(name):
            out.extend(_table_rules(name, files[name]))
    return out


def _text_rules(file_name: str, text: str) -> list[dict[str, Any]]:
    rules: list[dict[str, Any]] = []
    current: dict[str, Any] | None = None
    part = ""
    for number, raw in enumerate(text.split("\n"), start=1):
        line = raw.strip()
        match = RULE_LINE.match(raw)
        if match and current is None:
            current = {"name": (match.group(1) or match.group(2) or "").replace('\\"', '"'), "file": file_name,
                       "line": number, "when": [], "then": []}
            part = ""
            continue
        if current is None:
            continue
        if line == "end":
            rules.append(current)
            current = None
        elif line in ("when", "then"):
            part = line
        elif part and line and not line.startswith(("//", "#", "/*", "*")) and not ATTRIBUTE.match(line):
            current[part].append(line)
    return rules


def _table_rules(file_name: str, text: str) -> list[dict[str, Any]]:
    converted = decision_table.convert(file_name, text)
    if not converted.drl:
        return []
    try:
        sheet = decision_table.read_sheets(file_name, text)[0]
    except (decision_table.TableError, IndexError):
        return []
    labels = _labels(sheet.rows)
    out = []
    for index, line in enumerate(converted.drl.split("\n")):
        match = RULE_LINE.match(line)
        cell = converted.cells[index] if index < len(converted.cells) else None
        if not match or cell is None:
            continue
        row = sheet.rows[cell.row - 1] if 0 < cell.row <= len(sheet.rows) else []
        name = (match.group(1) or match.group(2) or "").replace('\\"', '"')
        sentence = " · ".join(f"{labels[c]}: {value.strip()}" if labels.get(c) else value.strip()
                              for c, value in enumerate(row) if value.strip() and value.strip() != name)
        out.append({"name": name, "file": file_name,
                    "row": cell.row, "sheet": converted.sheet, "when": [sentence] if sentence else [], "then": []})
    return out


def _labels(rows: list[list[str]]) -> dict[int, str]:
    """Column -> the table's column label (the row under the code templates, above the first rule
    row): the row right after the one holding CONDITION/ACTION headers, two rows down."""
    for r, row in enumerate(rows):
        if any(cell.strip().upper() in ("CONDITION", "ACTION") for cell in row):
            below = rows[r + 3] if r + 3 < len(rows) else []
            return {c: v.strip() for c, v in enumerate(below) if v.strip()}
    return {}
