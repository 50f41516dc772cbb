"""Small rule sets for the decision-table and scenario tests: a greetings table as CSV and as an
.xlsx workbook written by openpyxl (merged object-type cells, like a spreadsheet program would)."""

from __future__ import annotations

import io
from typing import Any

from gateway.engine.ruleset import encode_binary

TYPES = """package org.printeps.dt;

import org.printeps.gateway.Actions;

global Actions actions;

declare Group
    entrance : String
    kind : String
    size : int
end
"""

HEADER = [
    ["", "RuleSet", "org.printeps.dt"],
    ["", "Import", "org.printeps.gateway.Actions"],
    ["", "Variables", "org.printeps.gateway.Actions actions"],
    ["", "Notes", "Greetings by party kind and size"],
    [],
    ["", "RuleTable Greetings"],
    ["", "NAME", "CONDITION", "CONDITION", "ACTION", "PRIORITY", "ACTIVATION-GROUP"],
    ["", "", "$g: Group", "", "", "", ""],  # C8:D8 merged
    ["", "", "kind", "size >= $param", 'actions.say("pepper", "$param");', "", ""],
    ["", "Rule", "Kind", "At least", "Pepper says", "Priority", "Only one"],
]
ROWS = [
    ["", "Greet a pair", "pair", "2", "Welcome. Two seats?", "10", "greeting"],
    ["", "Greet a family", "family", "3", "Welcome, family!", "10", "greeting"],
    ["", "Greet anyone", "", "1", "Welcome!", "0", "greeting"],
]


def table_rows(rows: list[list[str]] | None = None) -> list[list[str]]:
    return [list(r) for r in HEADER] + [list(r) for r in (ROWS if rows is None else rows)]


def csv_text(rows: list[list[str]] | None = None) -> str:
    """The table as CSV (merged cells: each cell of the merge ends with '...')."""
    lines = []
    for r, row in enumerate(table_rows(rows), start=1):
        cells = list(row)
        if r == 8:
            cells[2] = cells[3] = "$g: Group..."
        out = []
        for value in cells:
            if "," in value or value.startswith('"'):
                value = '"' + value.replace('"', '""') + '"'
            out.append(value)
        lines.append(",".join(out).rstrip(","))
    return "\n".join(lines) + "\n"


def xlsx_bytes(rows: list[list[str]] | None = None, sheet: str = "Greetings", before: list[str] = (),
               numbers: bool = True, extra: Any = None) -> bytes:
    """The table as a workbook: object-type cell C8 merged over C8:D8, sizes and priorities as
    numbers; ``before`` adds empty sheets in front of it; ``extra(ws)`` may change the sheet."""
    import openpyxl

    wb = openpyxl.Workbook()
    ws = wb.active
    ws.title = sheet
    for r, row in enumerate(table_rows(rows), start=1):
        for c, value in enumerate(row, start=1):
            if value == "":
                continue
            if numbers and r > 10 and c in (4, 6) and value.lstrip("-").isdigit():
                ws.cell(r, c, int(value))
            else:
                ws.cell(r, c, value)
    ws.merge_cells("C8:D8")
    for index, name in enumerate(before):
        wb.create_sheet(name, index)
    if extra is not None:
        extra(ws)
    buffer = io.BytesIO()
    wb.save(buffer)
    return buffer.getvalue()


def xlsx_text(*args: Any, **kwargs: Any) -> str:
    """The workbook as ``files`` carries it (a data: URL)."""
    return encode_binary(xlsx_bytes(*args, **kwargs))


def files_with(table_name: str, text: str) -> dict[str, str]:
    return {"types.drl": TYPES, table_name: text}


def group(kind: str, size: int, entrance: str = "entrance") -> dict[str, Any]:
    return {"type": "Group", "entrance": entrance, "kind": kind, "size": size}
