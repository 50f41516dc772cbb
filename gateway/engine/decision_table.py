"""Spreadsheet decision tables (``.csv``, ``.xlsx``) in Drools' layout, converted to DRL.

Why our own converter: ``drools-decisiontables`` is not among the jars we can get, and the layout is
small and well documented. This module follows Drools' ``SpreadsheetCompiler`` /
``DefaultRuleSheetListener`` behaviour cell for cell, so a workbook made for Drools works here:

* Only the **first sheet** of a workbook is read (a CSV file is one sheet, named after the file).
* Outside tables, a row's first non-empty cell is a **keyword** and the next one its value:
  ``RuleSet`` (the package, default ``rule_table``), ``Import`` and ``Variables`` (comma-separated),
  ``Functions``, ``Queries``, ``Declare`` (DRL text), ``Sequential``, ``EscapeQuotes``, ``Notes`` and
  the rule attributes (``PRIORITY``, ``NO-LOOP``, …) applied to the whole package. Other text is a note.
* A cell starting with ``RuleTable`` opens a table (its name prefixes the rule names). Below it:
  the **header row** (``CONDITION``/``C``, ``ACTION``/``A``, ``NAME``/``N``, ``DESCRIPTION``/``I``,
  ``PRIORITY``/``P``, ``NO-LOOP``/``U``, ``ACTIVATION-GROUP``/``X``, ``AGENDA-GROUP``/``G``, …), the
  **object-type row** (``$c: Customer``; merged across columns, their constraints form one
  pattern; in CSV a merged cell ends with ``...``), the **template row** (``age >= $param``,
  ``age >= $1 && age <= $2`` with comma-separated cell values, ``forall(||){kind == "$"}``, or a bare
  field name: ``kind`` → ``kind == "value"``) and the **label row** (free text). Every following row
  is one rule until an empty row; an empty cell leaves its condition or action out of that rule.

Two things differ on purpose, both to give better errors: a rule row's value may not leave ``$2``
of a template unfilled, and problems are collected (not just the first) with the sheet and cell
they are in. The generated DRL puts each constraint on its own line and remembers which cell every
line came from, so Drools' own compile errors are reported at the cell too (``greetings.xlsx!
Greetings!C7: …``). The workbench's grid editor reads and writes tables through :func:`grid` and
:func:`write_grid`.
"""

from __future__ import annotations

import csv
import datetime as dt
import io
import re
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

from gateway.engine.errors import CompileError
from gateway.engine.ruleset import decode_binary, encode_binary

DEFAULT_PACKAGE = "rule_table"
MAX_UNZIPPED_BYTES = 50_000_000  # a workbook that inflates beyond this is refused (zip bombs)
MAX_CELLS = 200_000

# Header keyword -> (DRL attribute or role, one-letter short form, at most one such column).
CODES: dict[str, tuple[str, bool]] = {
    "CONDITION": ("C", False),
    "ACTION": ("A", False),
    "NAME": ("N", True),
    "DESCRIPTION": ("I", False),
    "PRIORITY": ("P", True),
    "DURATION": ("D", True),
    "TIMER": ("T", True),
    "CALENDARS": ("E", True),
    "NO-LOOP": ("U", True),
    "LOCK-ON-ACTIVE": ("L", True),
    "AUTO-FOCUS": ("F", True),
    "ACTIVATION-GROUP": ("X", True),
    "AGENDA-GROUP": ("G", True),
    "RULEFLOW-GROUP": ("R", True),
    "DATE-EFFECTIVE": ("V", True),
    "DATE-EXPIRES": ("Z", True),
    "METADATA": ("@", False),
}
_TAG_TO_CODE = {**{k: k for k in CODES}, **{short: k for k, (short, _) in CODES.items()}}
ATTRIBUTE_CODES = ("PRIORITY", "DURATION", "TIMER", "CALENDARS", "NO-LOOP", "LOCK-ON-ACTIVE",
                   "AUTO-FOCUS", "ACTIVATION-GROUP", "AGENDA-GROUP", "RULEFLOW-GROUP",
                   "DATE-EFFECTIVE", "DATE-EXPIRES")
_DRL_ATTRIBUTE = {"PRIORITY": "salience", "DURATION": "duration", "TIMER": "timer", "CALENDARS": "calendars",
                  "NO-LOOP": "no-loop", "LOCK-ON-ACTIVE": "lock-on-active", "AUTO-FOCUS": "auto-focus",
                  "ACTIVATION-GROUP": "activation-group", "AGENDA-GROUP": "agenda-group",
                  "RULEFLOW-GROUP": "ruleflow-group", "DATE-EFFECTIVE": "date-effective",
                  "DATE-EXPIRES": "date-expires"}
_BOOLEAN_ATTRIBUTES = {"NO-LOOP", "LOCK-ON-ACTIVE", "AUTO-FOCUS"}
_QUOTED_ATTRIBUTES = {"CALENDARS", "ACTIVATION-GROUP", "AGENDA-GROUP", "RULEFLOW-GROUP"}
KEYWORDS = ("RuleSet", "Import", "Variables", "Functions", "Queries", "Declare", "Sequential",
            "EscapeQuotes", "Notes", "NumericDisabled", "IgnoreNumericFormat", "Unit", "Dialect",
            *ATTRIBUTE_CODES)

# Drools' LhsBuilder: operators that, ending a bare template, take the cell value in quotes.
_OPERATORS = ("==", "=", "!=", "<", ">", "<=", ">=", "contains", "matches", "memberOf",
              "str[startsWith]", "str[endsWith]", "str[length]")
_FORALL = re.compile(r"forall\(([^{}]*)\)\{([^{}]+)\}")
_PAR_FROM = re.compile(r"\(\s*\)\s*from\b")
_FROM = re.compile(r"\s+from\s+")
_PAR_END = re.compile(r"\(\s*\)\s*\Z")
_EVAL = re.compile(r"\beval\s*(?:\(\s*\)\s*)?$")
_INDEXED = re.compile(r"\$(\d+)")


# --------------------------------------------------------------------------- cells and sheets


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


def sheet_error(file_name: str, cell: CellRef | None, message: str, sheet: str = "") -> CompileError:
    """A CompileError naming the sheet and cell (A1 of the sheet when no cell is known)."""
    if cell is None:
        return CompileError(file_name, 1 if sheet else 0, 1 if sheet else 0, message, sheet, "A1" if sheet else "")
    return CompileError(file_name, cell.row, cell.col, message, cell.sheet, cell.ref)


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


# --------------------------------------------------------------------------- templates


def _split_arguments(text: str) -> list[str]:
    """Drools' StringUtils.splitArgumentsList: commas outside quotes and brackets."""
    args: list[str] = []
    start, depth, quoted = 0, 0, False
    i = 0
    while i < len(text):
        ch = text[i]
        if ch == "," and not quoted and depth == 0:
            args.append(text[start:i].strip())
            start = i + 1
        elif ch in "([{" and not quoted:
            depth += 1
        elif ch in ")]}" and not quoted:
            depth -= 1
        elif ch in "\"'":
            quoted = not quoted
        elif ch == "\\" and i + 1 < len(text) and text[i + 1] == '"':
            i += 1
        i += 1
    last = text[start:].strip()
    if last:
        args.append(last)
    return args


def _replace(text: str, placeholder: str, value: str) -> str:
    return text.replace(placeholder, value.replace("\n", "\\n"))


def build_snippet(template: str, value: str) -> str:
    """Drools' SnippetBuilder: fill a template with a cell value. ValueError if ``$1``… are left."""
    if _FORALL.search(template):
        values = _split_arguments(value)

        def expand(match: re.Match[str]) -> str:
            return f" {match.group(1)} ".join(match.group(2).replace("$", v.strip()) for v in values)

        return _FORALL.sub(expand, template) or template
    if "$1" in template:
        values = _split_arguments(value)
        wanted = max(int(n) for n in _INDEXED.findall(template))
        if len(values) < wanted:
            raise ValueError(f"the template {template!r} takes {wanted} comma-separated values; "
                             f"this cell has {len(values)}")
        result = template
        for number in range(len(values), 0, -1):  # $10 before $1
            result = _replace(result, f"${number}", values[number - 1].strip())
        return result
    return _replace(template, "$param", value)


def _is_delimited(text: str) -> bool:
    return len(text) >= 2 and any(text[0] == a and text.find(b, 1) == len(text) - 1
                                  for a, b in (('"', '"'), ("\u201c", "\u201d"), ("\u201c", "\u201c"), ("\u201d", "\u201d")))


class _Lhs:
    """The conditions of one column group (Drools' LhsBuilder). With an object type (``$c:
    Customer``) every column adds a constraint to that one pattern; without, each cell is a
    whole condition."""

    def __init__(self, header: CellRef | None, column_def: str):
        self.header = header
        self.templates: dict[int, tuple[str, str]] = {}  # col -> (template, field kind)
        self.values: list[tuple[str, CellRef]] = []
        self.multiple = bool(column_def)
        self.forall = False
        self.andop = ", "
        self.prefix = self.suffix = ""
        if not column_def:
            return
        if (m := _EVAL.search(column_def)) is not None:
            self.prefix, self.suffix, self.andop = column_def[:m.start()] + "eval(", ")", " && "
        elif (m := _PAR_FROM.search(column_def)) is not None:
            self.prefix, self.suffix = column_def[:m.start()] + "(", ") from" + column_def[m.end():]
        elif (m := _FROM.search(column_def)) is not None:
            self.prefix, self.suffix = column_def[:m.start()] + "(", ") from " + column_def[m.end():]
        elif (m := _PAR_END.search(column_def)) is not None:
            self.prefix, self.suffix = column_def[:m.start()] + "(", ")" + column_def[m.end():]
        else:
            self.prefix, self.suffix = column_def + "(", ")"

    def add_template(self, col: int, content: str) -> None:
        content = content.strip()
        if _FORALL.search(content):
            kind = "forall"
        elif "$1" in content or "$param" in content:
            kind = "normal"
        elif any(content.endswith(op) for op in _OPERATORS):
            kind = "operator"
        else:
            kind = "single"
        if self.multiple and kind == "forall":
            self.forall = True
        elif self.multiple and kind == "single":
            content += ' == "$param"'
        elif self.multiple and kind == "operator":
            content += ' "$param"'
        self.templates[col] = (content, kind)

    def add_value(self, col: int, value: str, cell: CellRef) -> None:
        template, kind = self.templates[col]
        if self.multiple and kind in ("single", "operator") and not self.forall and _is_delimited(value):
            value = value[1:-1]
        self.values.append((build_snippet(template, value), cell))

    def lines(self) -> list[tuple[str, CellRef | None]]:
        if not self.multiple:
            return [(text, cell) for text, cell in self.values]
        out: list[tuple[str, CellRef | None]] = [(self.prefix, self.header)]
        separator = self.andop.rstrip()
        for i, (text, cell) in enumerate(self.values):
            out.append(("    " + text + (separator if i < len(self.values) - 1 else ""), cell))
        out.append((self.suffix, self.header))
        return out


class _Rhs:
    """The actions of one column group (Drools' RhsBuilder); an object-type cell holds a bound
    variable whose methods the templates call (``$c`` + ``setCategory("$param")``)."""

    def __init__(self, header: CellRef | None, variable: str, metadata: bool = False):
        self.header = header
        self.variable = variable.strip()
        self.metadata = metadata
        self.templates: dict[int, tuple[str, str]] = {}
        self.values: list[tuple[str, CellRef]] = []

    def add_template(self, col: int, content: str) -> None:
        content = content.strip()
        if self.variable:
            content = f"{self.variable}.{content};"
        self.templates[col] = (content, "normal")

    def add_value(self, col: int, value: str, cell: CellRef) -> None:
        self.values.append((build_snippet(self.templates[col][0], value), cell))

    def lines(self) -> list[tuple[str, CellRef | None]]:
        return [(text, cell) for text, cell in self.values]


@dataclass
class _Column:
    code: str
    header: CellRef
    builder: _Lhs | _Rhs | None = None
    object_cell: CellRef | None = None
    template_cell: CellRef | None = None
    label: str = ""


@dataclass
class _Rule:
    name: str
    name_cell: CellRef
    row_cell: CellRef
    table: str
    table_cell: CellRef
    description: tuple[str, CellRef] | None = None
    attributes: dict[str, tuple[str, CellRef]] = field(default_factory=dict)
    metadata: list[tuple[str, CellRef | None]] = field(default_factory=list)
    conditions: list[tuple[str, CellRef | None]] = field(default_factory=list)
    actions: list[tuple[str, CellRef | None]] = field(default_factory=list)
    cells: int = 0


# --------------------------------------------------------------------------- the sheet listener


class _SheetCompiler:
    """Drools' DefaultRuleSheetListener as a single pass over a sheet's cells."""

    def __init__(self, sheet: Sheet):
        self.sheet = sheet
        self.errors: list[TableError] = []
        self.properties: dict[str, list[tuple[str, CellRef]]] = {}
        self._row_property: dict[int, list[Any]] = {}
        self.rules: list[_Rule] = []
        self.tables: list[CellRef] = []
        self.in_table = False
        self.start_row = self.start_col = 0
        self.rule_row = 0
        self.table_name = ""
        self.columns: dict[int, _Column] = {}
        self.builders: list[_Lhs | _Rhs] = []
        self.current: _Rule | None = None
        self.sequential = False
        self.escape_quotes = True

    def cell(self, row: int, col: int) -> CellRef:
        return CellRef(self.sheet.name, row, col)

    def run(self) -> None:
        last_row = 0
        for row, col, text, merged_start in self.sheet.cells():
            if row != last_row:
                self.flush()
                last_row = row
            problem = self.sheet.problems.get((row, col))
            if not text.strip() and not problem:
                continue
            try:
                if problem:
                    raise TableError(self.cell(row, col), problem)
                self.new_cell(row, col, text, merged_start)
            except TableError as err:
                self.errors.append(err)
        self.flush()
        self.finish_properties()

    # -- outside tables: keyword cells

    def property_cell(self, row: int, col: int, text: str) -> None:
        entry = self._row_property.get(row)
        if entry is None:
            self._row_property[row] = [text.strip(), "", self.cell(row, col + 1), self.cell(row, col)]
        elif entry[1] == "":
            entry[1], entry[2] = text, self.cell(row, col)

    def finish_properties(self) -> None:
        for key, value, cell, key_cell in self._row_property.values():
            self.properties.setdefault(key.lower(), []).append((value, cell))
            if value and key.lower() not in {k.lower() for k in KEYWORDS}:
                near = _near_keyword(key)
                if near:
                    self.errors.append(TableError(key_cell, f"unknown keyword {key!r}: did you mean {near!r}?"))
        self._row_property.clear()

    def prop(self, key: str) -> list[tuple[str, CellRef]]:
        self.finish_properties()
        return self.properties.get(key.lower(), [])

    def single(self, key: str, default: str) -> str:
        values = self.prop(key)
        return values[0][0] if values and values[0][0] else default

    # -- cells

    def new_cell(self, row: int, col: int, text: str, merged_start: int | None) -> None:
        value = text.strip()
        if self.in_table and row == self.start_row:
            return  # other cells on the RuleTable row are notes
        if value.lower().startswith("ruletable"):
            self.start_table(row, col, value)
            return
        if not self.in_table:
            self.property_cell(row, col, text)
            return
        if col < self.start_col:
            return  # notes left of the table
        offset = row - self.start_row
        if offset == 1:
            self.header_cell(row, col, value)
        elif offset == 2:
            self.object_cell(row, col, value, merged_start)
        elif offset == 3:
            self.template_cell(row, col, value)
        elif offset == 4:
            self.column(row, col).label = value
        else:
            self.data_cell(row, col, value, merged_start)

    def start_table(self, row: int, col: int, value: str) -> None:
        self.flush()
        self.in_table = True
        self.start_row, self.start_col = row, col
        self.rule_row = row + 5
        self.table_name = value[len("ruletable"):].strip()
        self.columns = {}
        self.builders = []
        self.current = None
        self.tables.append(self.cell(row, col))
        self.sequential = _means_true(self.single("Sequential", "false"))
        self.escape_quotes = _means_true(self.single("EscapeQuotes", "true"))

    def column(self, row: int, col: int) -> _Column:
        column = self.columns.get(col)
        if column is None:
            raise TableError(self.cell(row, col), f"column {column_letters(col)} has no CONDITION, ACTION or "
                                                  f"attribute in its header cell {cell_name(self.start_row + 1, col)}")
        return column

    def header_cell(self, row: int, col: int, value: str) -> None:
        upper = value.upper()
        code = _TAG_TO_CODE.get(upper) or _TAG_TO_CODE.get(upper[:1])
        if code is None:
            raise TableError(self.cell(row, col), f"invalid column header {value!r}: use CONDITION, ACTION or an "
                                                  "attribute (NAME, PRIORITY, NO-LOOP, ACTIVATION-GROUP, …)")
        if CODES[code][1] and any(c.code == code for c in self.columns.values()):
            raise TableError(self.cell(row, col), f"a table has at most one {code} column")
        self.columns[col] = _Column(code, self.cell(row, col))

    def object_cell(self, row: int, col: int, value: str, merged_start: int | None) -> None:
        if "$param" in value or "$1" in value:
            raise TableError(self.cell(row, col), "this row is for object types ($c: Customer); the templates "
                                                  "($param, $1) go in the row below it: insert a row")
        column = self.column(row, col)
        column.object_cell = self.cell(row, merged_start or col)
        if merged_start is not None and col != merged_start:
            start = self.columns.get(merged_start)
            if start is not None and column.code == start.code:
                column.builder = start.builder
            return
        if column.code == "CONDITION":
            column.builder = _Lhs(self.cell(row, col), value)
        elif column.code == "ACTION":
            column.builder = _Rhs(self.cell(row, col), value)
        else:
            return
        self.builders.append(column.builder)

    def template_cell(self, row: int, col: int, value: str) -> None:
        column = self.column(row, col)
        column.template_cell = self.cell(row, col)
        if column.builder is None:
            if column.code == "CONDITION":
                column.builder = _Lhs(None, "")
            elif column.code == "ACTION":
                column.builder = _Rhs(None, "")
            elif column.code == "METADATA":
                column.builder = _Rhs(None, "", metadata=True)
            elif column.code == "PRIORITY":
                return  # Drools accepts and ignores a template here
            else:
                raise TableError(self.cell(row, col), f"unexpected {value!r} in the template row of a {column.code} "
                                                      "column: leave this cell empty")
            self.builders.append(column.builder)
        column.builder.add_template(col, value)

    def data_cell(self, row: int, col: int, value: str, merged_start: int | None) -> None:
        if row - self.rule_row > 1:  # an empty row ends the table; what follows is outside it
            self.flush()
            self.in_table = False
            self.new_cell(row, col, value, merged_start)
            return
        column = self.column(row, col)
        cell = self.cell(row, col)
        if self.current is None or row > self.rule_row or self.current.row_cell.row != row:
            if row > self.rule_row:
                self.rule_row += 1
            self.new_rule(row)
        rule = self.current
        assert rule is not None
        rule.cells += 1
        code = column.code
        if code in ("CONDITION", "ACTION", "METADATA"):
            if column.builder is None:
                raise TableError(cell, f"column {column_letters(col)} has no object type and no template above "
                                       f"this cell (rows {self.start_row + 2} and {self.start_row + 3})")
            if col not in column.builder.templates:
                raise TableError(cell, f"column {column_letters(col)} has no template in "
                                       f"{cell_name(self.start_row + 3, col)} for this value")
            if self.escape_quotes and value.find('"') > 0:
                value = value.replace('"', '\\"')
            try:
                column.builder.add_value(col, value, cell)
            except ValueError as exc:
                raise TableError(cell, str(exc)) from None
        elif code == "PRIORITY":
            if self.sequential:
                return
            if not (value.startswith("(") and value.endswith(")")):
                try:
                    value = str(int(value))
                except ValueError:
                    raise TableError(cell, f"PRIORITY must be a whole number, not {value!r}") from None
            rule.attributes[code] = (value, cell)
        elif code == "NAME":
            rule.name, rule.name_cell = _string_literal(value), cell
        elif code == "DESCRIPTION":
            rule.description = (value, cell)
        elif code == "DURATION":
            try:
                rule.attributes[code] = (str(int(value)), cell)
            except ValueError:
                raise TableError(cell, f"DURATION must be a whole number of milliseconds, not {value!r}") from None
        else:
            rule.attributes[code] = (_attribute_value(code, value), cell)

    def new_rule(self, row: int) -> None:
        rule = _Rule(
            name=_string_literal(f"{self.table_name}_{row}"),
            name_cell=self.cell(row, self.start_col),
            row_cell=self.cell(row, self.start_col),
            table=self.table_name,
            table_cell=self.cell(self.start_row, self.start_col),
        )
        if self.sequential:
            rule.attributes["PRIORITY"] = (str(65535 - (row - 1)), self.cell(row, self.start_col))
        self.current = rule
        self.rules.append(rule)

    def flush(self) -> None:
        """At the end of a row: the column groups that got values become the row's conditions
        and actions, in the order the groups were defined (as Drools does)."""
        if self.current is None:
            for builder in self.builders:
                builder.values.clear()
            return
        for builder in self.builders:
            if not builder.values:
                continue
            lines = builder.lines()
            if isinstance(builder, _Lhs):
                self.current.conditions.extend(lines)
            elif builder.metadata:
                self.current.metadata.extend(lines)
            else:
                self.current.actions.extend(lines)
            builder.values.clear()


def _means_true(value: str | None) -> bool:
    """Drools' isStringMeaningTrue: true, on, or anything starting with Y/y."""
    value = (value or "").strip()
    return value.lower() in ("true", "on") or value.startswith(("Y", "y"))


def _string_literal(value: str) -> str:
    if len(value) >= 2 and value.startswith('"') and value.endswith('"'):
        value = value[1:-1]
    return '"' + value.replace('"', '\\"') + '"'


def _attribute_value(code: str, value: str) -> str:
    if code in _BOOLEAN_ATTRIBUTES:
        return "true" if _means_true(value) else "false"
    if code in _QUOTED_ATTRIBUTES:
        return _string_literal(value)
    if code == "TIMER":
        return value if value.startswith("(") and value.endswith(")") else f"({value})"
    if code in ("DATE-EFFECTIVE", "DATE-EXPIRES"):
        return _string_literal(value)
    return value


def _near_keyword(key: str) -> str | None:
    import difflib

    found = difflib.get_close_matches(key.strip().rstrip(":").lower(), [k.lower() for k in KEYWORDS], n=1, cutoff=0.8)
    if not found:
        return None
    return next(k for k in KEYWORDS if k.lower() == found[0])


# --------------------------------------------------------------------------- DRL


@dataclass
class ConvertedTable:
    """The DRL a table becomes, the cell behind each DRL line, and the table's own problems."""

    file: str
    sheet: str
    drl: str | None
    cells: list[CellRef | None]
    errors: list[CompileError]
    package: str = DEFAULT_PACKAGE
    anchor: CellRef | None = None
    rule_count: int = 0

    def locate(self, error: CompileError) -> CompileError:
        """A compile error of the generated DRL, moved to the cell its line came from."""
        if error.file != self.file or error.cell:
            return error
        cell = None
        lines = (self.drl or "").split("\n")
        if 0 < error.line <= len(self.cells):
            cell = self.cells[error.line - 1]
        cell = cell or self.anchor
        message = error.message
        if 0 < error.line <= len(lines) and lines[error.line - 1].strip():
            message += f" (generated line: {lines[error.line - 1].strip()})"
        if self.package == DEFAULT_PACKAGE and "unknown type" in message:
            message += (f" — the table has no RuleSet cell, so its rules are in package {DEFAULT_PACKAGE}: "
                        "put RuleSet and your types' package above the RuleTable")
        return sheet_error(self.file, cell, message, self.sheet)


def convert(file_name: str, text: str) -> ConvertedTable:
    """A decision table file (``files`` text) -> its DRL, with cell-located problems."""
    try:
        sheets = read_sheets(file_name, text)
    except TableError as err:
        return ConvertedTable(file_name, "", None, [], [CompileError(file_name, 0, 0, err.message)])
    if not sheets:
        return ConvertedTable(file_name, "", None, [], [CompileError(file_name, 0, 0, "the workbook has no sheets")])
    sheet = sheets[0]
    compiler = _SheetCompiler(sheet)
    compiler.run()
    if not compiler.tables:
        errors = [sheet_error(file_name, e.cell, e.message, sheet.name) for e in compiler.errors]
        others = [s.name for s in sheets[1:] if any(t.strip().lower().startswith("ruletable") for row in s.rows for t in row)]
        hint = (f"; sheet {others[0]!r} has one, but only the first sheet is read: move it to the front"
                if others else ": a table starts with a cell 'RuleTable <name>'")
        errors.append(sheet_error(file_name, None, f"no RuleTable in sheet {sheet.name!r}{hint}", sheet.name))
        return ConvertedTable(file_name, sheet.name, None, [], errors)
    drl, cells, package = _render(file_name, sheet.name, compiler)
    errors = [sheet_error(file_name, e.cell, e.message, sheet.name) for e in compiler.errors]
    rules = [r for r in compiler.rules if r.cells]
    return ConvertedTable(file_name, sheet.name, drl, cells, errors, package, compiler.tables[0], len(rules))


def _render(file_name: str, sheet: str, comp: _SheetCompiler) -> tuple[str, list[CellRef | None], str]:
    out: list[tuple[str, CellRef | None]] = []
    add = out.append
    add((f"// Generated from {file_name} (sheet {sheet!r}), a decision table: edit the table, not this text.", None))
    ruleset = comp.prop("RuleSet")
    package = (ruleset[0][0].strip() if ruleset and ruleset[0][0].strip() else DEFAULT_PACKAGE).replace(" ", "_")
    add((f"package {package};", ruleset[0][1] if ruleset else None))
    add(("", None))
    for value, cell in comp.prop("Import"):
        for name in value.split(","):
            if name.strip():
                add((f"import {name.strip()};", cell))
    for value, cell in comp.prop("Variables"):
        for declaration in value.split(","):
            parts = declaration.split()
            if len(parts) != 2:
                comp.errors.append(TableError(cell, f"Variables: write each global as 'Type name' (comma-separated), "
                                                    f"not {declaration.strip()!r}"))
                continue
            add((f"global {parts[0]} {parts[1]};", cell))
    for key in ("Unit", "Dialect"):
        for _, cell in comp.prop(key):
            comp.errors.append(TableError(cell, f"{key} is not supported here (the gateway compiles with the "
                                                "executable model and the java dialect)"))
    for key in ("Functions", "Queries", "Declare"):
        for value, cell in comp.prop(key):
            for line in value.split("\n"):
                add((line, cell))
    for code in ATTRIBUTE_CODES:
        values = comp.prop(code)
        if len(values) > 1:
            comp.errors.append(TableError(values[1][1], f"{code} is set more than once for the rule set "
                                                        f"(also in {values[0][1].ref})"))
        if values and values[0][0]:
            value, cell = values[0]
            if code in ("PRIORITY", "DURATION") and not re.fullmatch(r"-?\d+", value.strip()):
                comp.errors.append(TableError(cell, f"{code} must be a whole number, not {value!r}"))
                continue
            add((f"{_DRL_ATTRIBUTE[code]} {_attribute_value(code, value.strip())}", cell))
    for rule in comp.rules:
        if not rule.cells:
            continue
        add(("", None))
        table = rule.table_cell
        add((f"// RuleTable {rule.table} ({sheet}!{table.ref}), row {rule.row_cell.row}", rule.row_cell))
        add((f"rule {rule.name}", rule.name_cell))
        if rule.description:
            add((f"    // {rule.description[0]}", rule.description[1]))
        for text, cell in rule.metadata:
            add((f"    @{text}", cell))
        for code, (value, cell) in rule.attributes.items():
            add((f"    {_DRL_ATTRIBUTE[code]} {value}", cell))
        add(("when", rule.row_cell))
        for text, cell in rule.conditions:
            add(("    " + text, cell))
        add(("then", rule.row_cell))
        for text, cell in rule.actions:
            add(("    " + text, cell))
        add(("end", rule.row_cell))
    lines, cells = [], []
    for text, cell in out:
        for part in text.split("\n"):
            lines.append(part)
            cells.append(cell)
    return "\n".join(lines) + "\n", cells, package


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


def is_table(file_name: str) -> bool:
    return file_name.endswith((".csv", ".xlsx")) and "/" not in file_name


__all__ = ["CellRef", "ConvertedTable", "Sheet", "TableError", "build_snippet", "column_letters", "convert",
           "csv", "grid", "is_table", "read_sheets", "write_grid"]
