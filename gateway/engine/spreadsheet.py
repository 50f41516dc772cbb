"""Spreadsheets as text: the cells of a ``.csv`` or ``.xlsx`` decision table, and back.

Why separate from the converter: reading a workbook (openpyxl, merged ranges, formulas, number
formats as Drools' ExcelParser formats them) and writing edited cells back into it (keeping styles,
formulas and other sheets) are file-format concerns; :mod:`gateway.engine.decision_table` only sees
:class:`Sheet` objects (cell texts). A CSV file is one sheet named after the file and read line by line
as Drools' CsvParser does (a quoted cell cannot span lines; a merged cell ends with ``...``).
"""

from __future__ import annotations

import datetime as dt
import io
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

from gateway.engine.ruleset import decode_binary, encode_binary

MAX_UNZIPPED_BYTES = 50_000_000  # a workbook that inflates beyond this is refused (zip bombs)
MAX_CELLS = 200_000


def column_letters(col: int) -> str:
    """1 -> A, 26 -> Z, 27 -> AA."""
    letters = ""
    while col > 0:
        col, rest = divmod(col - 1, 26)
        letters = chr(ord("A") + rest) + letters
    return letters


def cell_name(row: int, col: int) -> str:
    return f"{column_letters(col)}{row}"


@dataclass(frozen=True)
class CellRef:
    """A cell of a sheet; ``row`` and ``col`` are 1-based, as a spreadsheet shows them."""

    sheet: str
    row: int
    col: int

    @property
    def ref(self) -> str:
        return cell_name(self.row, self.col)


@dataclass
class Sheet:
    """One sheet as text: ``rows[r][c]`` is the cell's text ("" when empty), rows may be ragged.

    ``merged`` holds merged ranges as (first row, first col, last row, last col), 1-based; a CSV
    sheet has none (it marks merged cells with a trailing ``...`` instead). ``problems`` are cells
    that could not be read (e.g. a formula never computed), reported only if the table uses them.
    """

    name: str
    rows: list[list[str]]
    merged: list[tuple[int, int, int, int]] = field(default_factory=list)
    csv: bool = False
    problems: dict[tuple[int, int], str] = field(default_factory=dict)

    def cells(self) -> Iterator[tuple[int, int, str, int | None]]:
        """(row, col, text, first column of its merged range or None), row by row, as Drools'
        parsers report them: inside a merged range every cell carries the range's first value."""
        anchors: dict[tuple[int, int], tuple[int, int]] = {}
        widths: dict[int, int] = {}
        for r1, c1, r2, c2 in self.merged:
            for r in range(r1, r2 + 1):
                widths[r] = max(widths.get(r, 0), c2)
                for c in range(c1, c2 + 1):
                    anchors[(r, c)] = (r1, c1)
        for r, row in enumerate(self.rows, start=1):
            merge_start: int | None = None
            width = max(len(row), widths.get(r, 0))
            for c in range(1, width + 1):
                text = row[c - 1] if c <= len(row) else ""
                if self.csv:
                    if text.endswith("..."):
                        merge_start = c if merge_start is None else merge_start
                        yield r, c, text[:-3], merge_start
                    else:
                        merge_start = None
                        yield r, c, text, None
                    continue
                anchor = anchors.get((r, c))
                if anchor is None:
                    yield r, c, text, None
                else:
                    ar, ac = anchor
                    yield r, c, self.text(ar, ac), ac

    def text(self, row: int, col: int) -> str:
        if 0 < row <= len(self.rows) and 0 < col <= len(self.rows[row - 1]):
            return self.rows[row - 1][col - 1]
        return ""


class TableError(Exception):
    """A problem at a cell (or with the whole file when ``cell`` is None)."""

    def __init__(self, cell: CellRef | None, message: str):
        super().__init__(message)
        self.cell = cell
        self.message = message


def read_sheets(file_name: str, text: str) -> list[Sheet]:
    """The sheets of a table file (``files`` text: CSV text, or an .xlsx data: URL)."""
    if file_name.endswith(".csv"):
        return [_read_csv(file_name, text)]
    if file_name.endswith(".xlsx"):
        return _read_xlsx(file_name, text)
    raise TableError(None, "not a decision table file (.csv or .xlsx)")


def _read_csv(file_name: str, text: str) -> Sheet:
    """One row per line, as Drools' CsvParser reads it (a quoted cell cannot span lines)."""
    rows = [_csv_line(line.rstrip("\r")) for line in text.split("\n")]
    while rows and not any(rows[-1]):
        rows.pop()
    return Sheet(Path(file_name).stem, rows, csv=True)


def _csv_line(line: str) -> list[str]:
    """Drools' CsvLineParser: comma-separated, a cell may be quoted with "" for a quote inside."""
    cells: list[str] = []
    i, n = 0, len(line)
    if n == 0:
        return []
    while True:
        buf: list[str] = []
        if i < n and line[i] == '"':
            j = i + 1
            while j < n:
                ch = line[j]
                if ch == '"' and j + 1 < n:
                    if line[j + 1] == '"':
                        buf.append('"')
                        j += 2
                        continue
                    if line[j + 1] == ",":
                        j += 1
                        break
                elif ch == '"' and j + 1 == n:
                    break
                buf.append(ch)
                j += 1
            i = j
        else:
            j = line.find(",", i)
            if j < 0:
                buf.append(line[i:])
                i = n
            else:
                buf.append(line[i:j])
                i = j
        cells.append("".join(buf))
        i += 1
        if i >= n:
            break
    return cells


def _read_xlsx(file_name: str, text: str) -> list[Sheet]:
    try:
        data = decode_binary(file_name, text)
    except ValueError as exc:
        raise TableError(None, str(exc)) from None
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            inflated = sum(info.file_size for info in zf.infolist())
    except zipfile.BadZipFile:
        raise TableError(None, "not an .xlsx workbook (the file is not a zip archive; .xls files are "
                               "not supported: save it as .xlsx)") from None
    if inflated > MAX_UNZIPPED_BYTES:
        raise TableError(None, f"the workbook inflates to {inflated} bytes (at most {MAX_UNZIPPED_BYTES})")
    import openpyxl

    try:
        values = openpyxl.load_workbook(io.BytesIO(data), data_only=True)
        formulas = openpyxl.load_workbook(io.BytesIO(data), data_only=False)
    except Exception as exc:  # openpyxl raises many kinds (KeyError, InvalidFileException, …)
        raise TableError(None, f"not a readable .xlsx workbook: {type(exc).__name__}: {exc}") from None
    sheets: list[Sheet] = []
    for ws in values.worksheets:
        wf = formulas[ws.title]
        if ws.max_row * ws.max_column > MAX_CELLS:
            raise TableError(None, f"sheet {ws.title!r} has {ws.max_row} x {ws.max_column} cells (at most {MAX_CELLS})")
        rows: list[list[str]] = []
        problems: dict[tuple[int, int], str] = {}
        for r in range(1, ws.max_row + 1):
            row: list[str] = []
            for c in range(1, ws.max_column + 1):
                value = ws.cell(r, c).value
                if value is None:
                    formula = wf.cell(r, c).value
                    if isinstance(formula, str) and formula.startswith("="):
                        problems[(r, c)] = (f"the formula {formula} has no computed value (the file was not "
                                            "saved by a spreadsheet program): type the value instead")
                row.append(format_value(value))
            while row and row[-1] == "":
                row.pop()
            rows.append(row)
        while rows and not rows[-1]:
            rows.pop()
        merged = [(m.min_row, m.min_col, m.max_row, m.max_col) for m in ws.merged_cells.ranges]
        sheets.append(Sheet(ws.title, rows, merged, problems=problems))
    return sheets


def format_value(value: Any) -> str:
    """A cell value as the text Drools' ExcelParser reads: whole numbers without ".0", booleans as
    true/false, dates quoted as dd-MMM-yyyy."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return str(int(value)) if value.is_integer() else repr(value)
    if isinstance(value, (dt.datetime, dt.date)):
        return '"' + value.strftime("%d-%b-%Y") + '"'
    return str(value)


# --------------------------------------------------------------------------- the workbench's grid


def grid(file_name: str, text: str) -> dict[str, Any]:
    """A table file as the workbench's grid shows it: every sheet's cell texts and merged ranges
    (``"C9:D9"``); ``table_sheet`` is the one the rules come from."""
    try:
        sheets = read_sheets(file_name, text)
    except TableError as err:
        raise ValueError(f"{file_name}: {err.message}") from None
    return {
        "file": file_name,
        "table_sheet": sheets[0].name if sheets else "",
        "sheets": [
            {"name": s.name, "rows": s.rows,
             "merged": [f"{cell_name(r1, c1)}:{cell_name(r2, c2)}" for r1, c1, r2, c2 in s.merged]}
            for s in sheets
        ],
    }


_RANGE = re.compile(r"^([A-Z]{1,3})(\d+):([A-Z]{1,3})(\d+)$")


def _column_number(letters: str) -> int:
    n = 0
    for ch in letters:
        n = n * 26 + ord(ch) - ord("A") + 1
    return n


def write_grid(file_name: str, text: str, sheet_name: str, rows: list[list[str]],
               merged: list[str] | None = None) -> str:
    """A table file (``files`` text) with ``sheet_name``'s cells replaced by ``rows``; for a workbook
    everything else (other sheets, styles, formulas left unchanged) is kept. ValueError naming the
    cell when a value cannot be written."""
    if not isinstance(rows, list) or not all(isinstance(r, list) and all(isinstance(v, str) for v in r) for r in rows):
        raise ValueError("rows must be a list of lists of strings")
    if file_name.endswith(".csv"):
        return _write_csv(rows)
    if not file_name.endswith(".xlsx"):
        raise ValueError(f"{file_name}: not a decision table file (.csv or .xlsx)")
    import openpyxl
    from openpyxl.cell.cell import MergedCell

    try:
        data = decode_binary(file_name, text)
        workbook = openpyxl.load_workbook(io.BytesIO(data))
        values = openpyxl.load_workbook(io.BytesIO(data), data_only=True)
    except Exception as exc:
        raise ValueError(f"{file_name}: not a readable .xlsx workbook: {exc}") from None
    if sheet_name not in workbook.sheetnames:
        raise ValueError(f"{file_name}: no sheet named {sheet_name!r} (sheets: {', '.join(workbook.sheetnames)})")
    ws, wv = workbook[sheet_name], values[sheet_name]
    ranges = _parse_ranges(merged) if merged is not None else None
    if ranges is not None:
        for existing in list(ws.merged_cells.ranges):
            ws.unmerge_cells(str(existing))
    height = max(ws.max_row, len(rows))
    width = max(ws.max_column, max((len(r) for r in rows), default=0))
    for r in range(1, height + 1):
        for c in range(1, width + 1):
            cell = ws.cell(r, c)
            if isinstance(cell, MergedCell):
                continue
            new = rows[r - 1][c - 1] if r <= len(rows) and c <= len(rows[r - 1]) else ""
            old_value = wv.cell(r, c).value if r <= wv.max_row and c <= wv.max_column else None
            if new == format_value(old_value):
                continue  # unchanged: keep the cell as it is (its type, its formula)
            cell.value = _typed(new, old_value)
    if ranges is not None:
        for r1, c1, r2, c2 in ranges:
            ws.merge_cells(start_row=r1, start_column=c1, end_row=r2, end_column=c2)
    buffer = io.BytesIO()
    workbook.save(buffer)
    return encode_binary(buffer.getvalue())


def _parse_ranges(merged: list[str]) -> list[tuple[int, int, int, int]]:
    out = []
    for text in merged:
        m = _RANGE.match(str(text).strip().upper())
        if not m:
            raise ValueError(f"merged range {text!r}: write it like C9:D9")
        r1, c1, r2, c2 = int(m.group(2)), _column_number(m.group(1)), int(m.group(4)), _column_number(m.group(3))
        out.append((min(r1, r2), min(c1, c2), max(r1, r2), max(c1, c2)))
    return out


def _typed(text: str, old: Any) -> Any:
    """A grid text as a cell value: empty clears; a number stays a number where one was (or looks
    like a whole number); everything else is text, as typed."""
    if text == "":
        return None
    if isinstance(old, bool) and text.lower() in ("true", "false"):
        return text.lower() == "true"
    if re.fullmatch(r"-?(0|[1-9]\d{0,14})", text):
        return int(text)
    if isinstance(old, (int, float)) and not isinstance(old, bool):
        try:
            return float(text)
        except ValueError:
            pass
    return text


def _write_csv(rows: list[list[str]]) -> str:
    """Rows as CSV that Drools' line parser reads back unchanged (one line per row)."""
    lines = []
    for r, row in enumerate(rows, start=1):
        cells = list(row)
        while cells and cells[-1] == "":
            cells.pop()
        out = []
        for c, value in enumerate(cells, start=1):
            if "\n" in value or "\r" in value:
                raise ValueError(f"{cell_name(r, c)}: a CSV cell cannot hold a line break")
            if "," in value or value.startswith('"'):
                value = '"' + value.replace('"', '""') + '"'
            out.append(value)
        lines.append(",".join(out))
    return "\n".join(lines) + "\n"
