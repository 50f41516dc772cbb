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
Greetings!C7: …``). Reading the files (and the workbench's grid I/O, :func:`grid` and
:func:`write_grid`) is :mod:`gateway.engine.spreadsheet`'s job.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from gateway.engine.errors import CompileError
from gateway.engine.spreadsheet import (  # noqa: F401 - grid/write_grid: the workbench's table I/O, re-exported
    CellRef, Sheet, TableError, cell_name, column_letters, grid, read_sheets, write_grid,
)

DEFAULT_PACKAGE = "rule_table"

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


def sheet_error(file_name: str, cell: CellRef | None, message: str, sheet: str = "") -> CompileError:
    """A CompileError naming the sheet and cell (A1 of the sheet when no cell is known)."""
    if cell is None:
        return CompileError(file_name, 1 if sheet else 0, 1 if sheet else 0, message, sheet, "A1" if sheet else "")
    return CompileError(file_name, cell.row, cell.col, message, cell.sheet, cell.ref)


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
        self.headings: dict[tuple[int, int], str] = {}  # value cell -> its column's label (or template)

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
            self.headings[(row, col)] = column.label or column.builder.templates[col][0]
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
    rows: list[list[str]] = field(default_factory=list, repr=False)  # the sheet's cell texts
    headings: dict[tuple[int, int], str] = field(default_factory=dict, repr=False)  # value cell -> column label

    def cell_text(self, cell: CellRef | None) -> str:
        """The text an author wrote in ``cell`` ("" for none): explain shows a table rule's
        conditions as their cells' texts, not only as where they are."""
        if cell is None or not 0 < cell.row <= len(self.rows) or not 0 < cell.col <= len(self.rows[cell.row - 1]):
            return ""
        text = self.rows[cell.row - 1][cell.col - 1].strip()
        return text[:-3].rstrip() if text.endswith("...") else text  # a CSV cell marked as merged

    def cell_words(self, cell: CellRef | None) -> str:
        """A cell as the author reads it in the table: ``At least: 2`` (its column's label, or
        template, and its text), or the text alone for a cell that is no rule value."""
        text = self.cell_text(cell)
        heading = self.headings.get((cell.row, cell.col)) if cell is not None else None
        return f"{heading}: {text}" if heading and text else text

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
    return ConvertedTable(file_name, sheet.name, drl, cells, errors, package, compiler.tables[0], len(rules),
                          rows=sheet.rows, headings=compiler.headings)


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


__all__ = ["CellRef", "ConvertedTable", "Sheet", "TableError", "build_snippet", "column_letters", "convert",
           "grid", "read_sheets", "sheet_error", "write_grid"]
