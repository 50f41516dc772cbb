"""Decision tables in Drools' spreadsheet layout (.csv and .xlsx, the workbooks written by openpyxl):
the conversion to DRL follows Drools' SpreadsheetCompiler, the rules fire on the real engine, and
every problem names its sheet and cell."""

from __future__ import annotations

import io

import pytest

from gateway.engine import CompileFailed, Engine
from gateway.engine import decision_table as dt
from gateway.engine.ruleset import decode_binary, encode_binary, read_folder, write_file

from authoring_samples import csv_text, files_with, group, table_rows, xlsx_text


def said(result) -> list[str]:
    return [a["params"]["text"] for a in result.actions if a["module"] == "say"]


def to_csv(rows: list[list[str]]) -> str:
    """Rows as CSV, quoted where a cell holds a comma or starts with a quote."""
    def quote(value: str) -> str:
        return '"' + value.replace('"', '""') + '"' if "," in value or value.startswith('"') else value
    return "\n".join(",".join(quote(v) for v in row) for row in rows) + "\n"


def convert_rows(rows: list[list[str]], name: str = "t.csv") -> dt.ConvertedTable:
    return dt.convert(name, to_csv(rows))


# --------------------------------------------------------------------------- conversion (no JVM)


def test_csv_and_xlsx_give_the_same_drl():
    from_csv = dt.convert("greetings.csv", csv_text())
    from_xlsx = dt.convert("greetings.xlsx", xlsx_text())
    assert from_csv.errors == [] and from_xlsx.errors == []
    body = lambda t: t.drl.split("\n", 1)[1].replace("(greetings!", "(Greetings!")  # noqa: E731 - the header line names the file
    assert body(from_csv) == body(from_xlsx)
    drl = from_xlsx.drl
    assert "package org.printeps.dt;" in drl and "import org.printeps.gateway.Actions;" in drl
    assert "global org.printeps.gateway.Actions actions;" in drl
    # One rule per row: NAME, PRIORITY and ACTIVATION-GROUP become the rule's name and attributes;
    # the merged object-type cell makes one pattern of both conditions; a bare field name compares
    # with the quoted value; an empty cell leaves its constraint out.
    assert '''rule "Greet a pair"
    salience 10
    activation-group "greeting"
when
    $g: Group(
        kind == "pair",
        size >= 2
    )
then
    actions.say("pepper", "Welcome. Two seats?");
end''' in drl
    assert '''rule "Greet anyone"
    salience 0
    activation-group "greeting"
when
    $g: Group(
        size >= 1
    )''' in drl
    assert from_xlsx.rule_count == 3 and from_xlsx.sheet == "Greetings"


def test_every_generated_line_knows_its_cell():
    table = dt.convert("greetings.xlsx", xlsx_text())
    lines = table.drl.split("\n")
    where: dict[str, str | None] = {}
    for line, cell in zip(lines, table.cells):
        where.setdefault(line.strip(), cell.ref if cell else None)
    assert where['kind == "pair",'] == "C11"
    assert where["size >= 2"] == "D11"
    assert where['actions.say("pepper", "Welcome. Two seats?");'] == "E11"
    assert where["$g: Group("] == "C8"
    assert where['rule "Greet a pair"'] == "B11"
    assert where["salience 10"] == "F11" and where["package org.printeps.dt;"] == "C1"


def test_templates_follow_drools_snippets():
    assert dt.build_snippet("age >= $param", "4") == "age >= 4"
    assert dt.build_snippet("age >= $1 && age <= $2", "4, 12") == "age >= 4 && age <= 12"
    assert dt.build_snippet('kind in ($1, $2)', '"a, b", "c"') == 'kind in ("a, b", "c")'  # quoted commas stay
    assert dt.build_snippet('forall(||){kind == "$"}', "pair, couple") == 'kind == "pair" || kind == "couple"'
    assert dt.build_snippet('say("$param")', "two\nlines") == 'say("two\\nlines")'
    with pytest.raises(ValueError, match="takes 2 comma-separated values; this cell has 1"):
        dt.build_snippet("age >= $1 && age <= $2", "4")


def test_keywords_attributes_and_quotes():
    rows = [
        ["RuleSet", "org.x"],
        ["Sequential", "true"],
        ["EscapeQuotes", "true"],
        ["NO-LOOP", "true"],
        [],
        ["RuleTable Sizes"],
        ["CONDITION", "ACTION", "NO-LOOP", "DESCRIPTION", "PRIORITY"],
        ["$g: Group", "$g", "", "", ""],
        ["size >", 'setKind("$param")', "", "", ""],
        ["Bigger than", "Kind", "", "", ""],
        ["4", 'big "party"', "Y", "more than four", "99"],
        ["", 'say 19" tall', "", "", ""],
        [],
        ["after the gap", "is a note"],
    ]
    table = convert_rows(rows)
    assert table.errors == []
    drl = table.drl
    assert "no-loop true" in drl.split("rule ")[0]  # a package attribute
    # Sequential: salience by row, top down (the PRIORITY column is ignored); an operator template
    # takes the value in quotes; a quote inside a value is escaped, one at its start is kept.
    assert "salience 65525" in drl and "salience 99" not in drl
    assert 'size > "4"' in drl
    assert '$g.setKind("big \\"party\\"");' in drl
    assert '$g.setKind("say 19\\" tall");' in drl
    assert "// more than four" in drl and "no-loop true\nwhen" in drl.replace("    ", "")
    assert "after the gap" not in drl  # an empty row ends the table


def test_notes_left_of_a_table_and_two_tables():
    rows = [
        ["", "RuleSet", "org.x"],
        [],
        ["", "RuleTable One"],
        ["", "CONDITION", "ACTION"],
        ["", "", ""],
        ["", "Group(kind == \"$param\")", "actions.say(\"pepper\", \"$param\");"],
        ["", "Kind", "Say"],
        ["a note", "pair", "Hi"],
        [],
        ["", "RuleTable Two"],
        ["", "C", "A"],
        ["", "", ""],
        ["", "Group(size > $param)", "actions.say(\"pepper\", \"$param\");"],
        ["", "", ""],
        ["", "3", "Big"],
    ]
    table = convert_rows(rows)
    assert table.errors == []
    assert 'rule "One_8"' in table.drl and 'rule "Two_15"' in table.drl
    assert "Group(kind == \"pair\")" in table.drl and "a note" not in table.drl


@pytest.mark.parametrize("change, cell, message", [
    ({(7, 3): "QUESTION"}, "C7", "invalid column header 'QUESTION'"),
    ({(7, 6): "PRIORITY", (7, 7): "P"}, "G7", "at most one PRIORITY column"),
    ({(8, 5): "$param"}, "E8", "this row is for object types"),
    ({(9, 4): ""}, "D11", "no template"),
    ({(11, 6): "high"}, "F11", "PRIORITY must be a whole number, not 'high'"),
    ({(11, 8): "stray"}, "H11", "column H has no CONDITION, ACTION or attribute in its header cell H7"),
    ({(2, 2): "Imports"}, "B2", "unknown keyword 'Imports': did you mean 'Import'?"),
    ({(3, 3): "org.printeps.gateway.Actions"}, "C3", "Variables: write each global as 'Type name'"),
    ({(9, 4): "size >= $1 && size <= $2"}, "D11", "takes 2 comma-separated values"),
])
def test_table_mistakes_name_the_sheet_and_cell(change, cell, message):
    rows = table_rows()
    for (r, c), value in change.items():
        while len(rows[r - 1]) < c:
            rows[r - 1].append("")
        rows[r - 1][c - 1] = value
    for name, text in (("t.csv", to_csv(rows)), ("t.xlsx", encode_binary(_workbook(rows)))):
        errors = dt.convert(name, text).errors
        assert errors, name
        first = errors[0]
        assert (first.cell, message in first.message) == (cell, True), (name, first)
        assert first.sheet == ("t" if name == "t.csv" else "Sheet")
        assert str(first).startswith(f"{name}!{first.sheet}!{cell}: ")


def _workbook(rows: list[list[str]]) -> bytes:
    import openpyxl

    wb = openpyxl.Workbook()
    ws = wb.active
    ws.title = "Sheet"
    for r, row in enumerate(rows, start=1):
        for c, value in enumerate(row, start=1):
            if value != "":
                ws.cell(r, c, value)
    buffer = io.BytesIO()
    wb.save(buffer)
    return buffer.getvalue()


def test_unreadable_workbooks_and_missing_tables():
    assert "data: URL" in dt.convert("a.xlsx", "PK not base64").errors[0].message
    broken = encode_binary(b"this is no zip")
    assert "not an .xlsx workbook" in dt.convert("a.xlsx", broken).errors[0].message
    # Drools reads the first sheet only: a table on another sheet is pointed at.
    later = dt.convert("a.xlsx", xlsx_text(before=["Cover"]))
    assert (later.errors[0].sheet, later.errors[0].cell) == ("Cover", "A1")
    assert "sheet 'Greetings' has one, but only the first sheet is read" in later.errors[0].message
    empty = dt.convert("a.csv", "just,a,note\n")
    assert "no RuleTable in sheet 'a'" in empty.errors[0].message


def test_a_formula_without_a_computed_value_is_named():
    text = xlsx_text(extra=lambda ws: ws.cell(11, 4, "=1+1"))
    errors = dt.convert("f.xlsx", text).errors
    assert errors[0].cell == "D11" and "formula =1+1 has no computed value" in errors[0].message


def test_grid_read_and_write_keep_the_workbook():
    original = xlsx_text(before=[], extra=lambda ws: ws.parent.create_sheet("Notes").cell(1, 1, "keep me"))
    grid = dt.grid("g.xlsx", original)
    assert grid["table_sheet"] == "Greetings" and [s["name"] for s in grid["sheets"]] == ["Greetings", "Notes"]
    sheet = grid["sheets"][0]
    assert sheet["merged"] == ["C8:D8"] and sheet["rows"][10][4] == "Welcome. Two seats?"
    rows = sheet["rows"]
    rows[10][4] = "Hello, you two!"
    rows.append(["", "Greet a trio", "trio", "3", "Three of you!", "5", "greeting"])
    written = dt.write_grid("g.xlsx", original, "Greetings", rows)
    again = dt.grid("g.xlsx", written)
    assert again["sheets"][0]["rows"][10][4] == "Hello, you two!"
    assert again["sheets"][0]["rows"][13][1] == "Greet a trio"
    assert again["sheets"][0]["merged"] == ["C8:D8"] and again["sheets"][1]["rows"] == [["keep me"]]
    import openpyxl

    ws = openpyxl.load_workbook(io.BytesIO(decode_binary("g.xlsx", written)))["Greetings"]
    assert ws["D11"].value == 2 and ws["D14"].value == 3  # numbers stay numbers
    assert "salience 5" in dt.convert("g.xlsx", written).drl
    # CSV: the grid writes what Drools' CSV reader reads back.
    csv_rows = dt.grid("g.csv", csv_text())["sheets"][0]["rows"]
    csv_rows[10][4] = 'Say "hi", please'
    again_csv = dt.write_grid("g.csv", csv_text(), "g", csv_rows)
    assert dt.grid("g.csv", again_csv)["sheets"][0]["rows"][10][4] == 'Say "hi", please'
    with pytest.raises(ValueError, match="C3: a CSV cell cannot hold a line break"):
        dt.write_grid("g.csv", "", "g", [[], [], ["", "", "two\nlines"]])


# --------------------------------------------------------------------------- on the engine


@pytest.fixture(scope="module")
def engine(tmp_path_factory) -> Engine:
    from gateway.config import Settings

    return Engine(Settings(data_dir=str(tmp_path_factory.mktemp("dt-data"))))


@pytest.mark.parametrize("name, text", [("greetings.csv", csv_text()), ("greetings.xlsx", xlsx_text())],
                         ids=["csv", "xlsx"])
def test_tables_fire(engine, name, text):
    files = files_with(name, text)
    assert said(engine.fire_files(files, [group("pair", 2)])) == ["Welcome. Two seats?"]
    assert said(engine.fire_files(files, [group("family", 4)])) == ["Welcome, family!"]
    assert said(engine.fire_files(files, [group("friends", 5)])) == ["Welcome!"]  # priority 0, same group
    assert said(engine.fire_files(files, [])) == []
    assert engine.expand("t", files)[name].startswith("// Generated from " + name)


def test_compile_errors_point_at_the_cell(engine):
    rows = table_rows()
    rows[8][3] = "sise >= $param"  # D9: a misspelt field
    errors = engine.validate("t", files_with("greetings.xlsx", encode_binary(_xlsx_from_rows(rows))))
    # every rule the misspelt column reaches is named, at its own cell (a whole build stops at the first)
    assert [(e.sheet, e.cell) for e in errors] == [("Greetings", "D11"), ("Greetings", "D12"), ("Greetings", "D13")]
    assert "sise >= 2" in errors[0].message
    rows = table_rows()
    rows[7][2] = rows[7][3] = "$g: Grup..."  # C8 (merged over D8 in CSV's way): an unknown type
    errors = engine.validate("t", files_with("greetings.csv", to_csv(rows)))
    assert [(e.cell, e.message.split(" (")[0]) for e in errors] == [("C8", "unknown type 'Grup'")]
    # Without a RuleSet cell the rules land in Drools' default package: the error says so.
    no_package = [r for r in table_rows() if r[1:2] != ["RuleSet"]]
    no_package[6][2] = no_package[6][3] = "$g: Group..."  # C7:D7 merged, CSV's way
    errors = engine.validate("t", files_with("t.csv", to_csv(no_package)))
    assert "no RuleSet cell" in errors[0].message


def test_a_broken_table_deploys_nothing(engine):
    engine.deploy("tables", files_with("greetings.xlsx", xlsx_text()))
    rows = table_rows()
    rows[10][5] = "high"
    with pytest.raises(CompileFailed) as failed:
        engine.deploy("tables", files_with("greetings.xlsx", encode_binary(_xlsx_from_rows(rows))))
    assert str(failed.value.errors[0]).startswith("greetings.xlsx!Greetings!F11: PRIORITY must be a whole number")
    assert engine.current("tables").info.version == 1
    assert said(engine.fire("tables", [group("pair", 2)])) == ["Welcome. Two seats?"]


def test_workbooks_and_tests_survive_versions_and_folders(engine, tmp_path):
    text = xlsx_text()
    files = {**files_with("greetings.xlsx", text), "tests/t.yaml": "- name: a\n  expect: {fired: [Greet a pair]}\n"}
    info = engine.deploy("kept", files, force=True)  # its one scenario is red: forced
    assert engine.version("kept", info.version).files == files  # the catalog keeps names and the data URL
    stored = tmp_path / "stored"
    for fname, content in files.items():
        write_file(stored / fname, content)
    assert read_folder(stored) == files
    assert (stored / "greetings.xlsx").read_bytes()[:2] == b"PK"  # the workbook itself on disk, not its text


def _xlsx_from_rows(rows: list[list[str]]) -> bytes:
    import openpyxl

    wb = openpyxl.Workbook()
    ws = wb.active
    ws.title = "Greetings"
    for r, row in enumerate(rows, start=1):
        for c, value in enumerate(row, start=1):
            if value != "":
                ws.cell(r, c, value)
    ws.merge_cells("C8:D8")
    buffer = io.BytesIO()
    wb.save(buffer)
    return buffer.getvalue()


def test_shipped_greetings_table_compiles(engine):
    from gateway.config import PROJECT_ROOT

    files = read_folder(PROJECT_ROOT / "rules" / "drl" / "reception_greetings")
    assert files["greetings.xlsx"].startswith("data:application/vnd.openxmlformats-officedocument.spreadsheetml.sheet;")
    assert engine.validate("reception_greetings", files) == []
    assert dt.convert("greetings.xlsx", files["greetings.xlsx"]).rule_count == 14


def test_the_documented_priority_error_is_where_rule_authoring_says(engine):
    """docs/rule-authoring.md, section 8: a PRIORITY that is not a number in the repository's
    greetings.xlsx is reported at J11 (the docs said F11, a cell of another layout)."""
    from pathlib import Path

    import openpyxl

    folder = Path(__file__).resolve().parents[2] / "rules" / "drl" / "reception_greetings"
    files = read_folder(folder)
    book = openpyxl.load_workbook(folder / "greetings.xlsx")
    book["Greetings"]["J11"] = "high"
    out = io.BytesIO()
    book.save(out)
    files["greetings.xlsx"] = encode_binary(out.getvalue())
    errors = engine.validate("reception_greetings", files)
    documented = next(line for line in (folder.parents[2] / "docs" / "rule-authoring.md").read_text().splitlines()
                      if "a `PRIORITY` that is not a number" in line).split("`")[-2]
    assert str(errors[0]) == documented
