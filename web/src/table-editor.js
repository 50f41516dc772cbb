// The decision-table grid editor: a .csv or .xlsx table of the rule set as a grid of cells. Each
// row below a table's header rows is one rule; editing a cell, adding or removing a row changes the
// file (the gateway rewrites the workbook, keeping its styles and other sheets), and the usual
// check-as-you-type marks problems at their cell ("greetings.xlsx!Greetings!C7").
// Self-contained: mountTableEditor(host, options) -> Promise<{content, flush, showProblems, reveal, setContent, dispose}>.

import { h, fill, debounce } from "./dom.js";
import { api } from "./api.js";

const WRITE_DELAY_MS = 250;

/** "C7" for row 7, column 3 (both 1-based). */
export function cellName(row, col) {
  let letters = "";
  for (let n = col; n > 0; n = Math.floor((n - 1) / 26)) letters = String.fromCharCode(65 + ((n - 1) % 26)) + letters;
  return `${letters}${row}`;
}

function parseRange(text) {
  const m = /^([A-Z]+)(\d+):([A-Z]+)(\d+)$/.exec(text);
  if (!m) return null;
  const col = (s) => [...s].reduce((n, ch) => n * 26 + ch.charCodeAt(0) - 64, 0);
  return { r1: +m[2], c1: col(m[1]), r2: +m[4], c2: col(m[3]) };
}

function rangeText(r) {
  return `${cellName(r.r1, r.c1)}:${cellName(r.r2, r.c2)}`;
}

/** Where the rule tables are: [{row, col}] of each "RuleTable …" cell (1-based). */
export function ruleTables(rows) {
  const found = [];
  rows.forEach((row, r) => row.forEach((text, c) => {
    if (/^\s*ruletable/i.test(text || "")) found.push({ row: r + 1, col: c + 1 });
  }));
  return found;
}

/**
 * Mount the grid for `fileName` in `host`. options: content (the file's text as in `files`),
 * readOnly, onChange(content) after every edit has been written into the file, onSelect(row) when
 * a row is selected (1-based, as the spreadsheet numbers it).
 */
export async function mountTableEditor(host, { fileName, content, readOnly = false, onChange = () => {}, onSelect = () => {} }) {
  const grid = await api("POST", "/api/decision-tables/read", { file: fileName, content });
  const editor = new TableEditor(host, fileName, content, grid, readOnly, onChange);
  editor.onSelect = onSelect;
  return editor;
}

class TableEditor {
  constructor(host, fileName, content, grid, readOnly, onChange) {
    this.host = host;
    this.fileName = fileName;
    this.text = content;
    this.readOnly = readOnly;
    this.onChange = onChange;
    this.sheets = grid.sheets;
    this.sheetName = grid.table_sheet || (grid.sheets[0] && grid.sheets[0].name) || "";
    this.problems = [];
    this.selected = { row: 1, col: 1 };
    this.writeSeq = 0;
    this.pending = null;
    this.scheduleWrite = debounce(() => this.write(), WRITE_DELAY_MS);
    this.statusEl = h("span", { class: "grid-status", "data-testid": "grid-status", "aria-live": "polite" });
    this.tableEl = h("table", { class: "grid", "data-testid": "grid", "data-file": fileName });
    this.sheetSelect = h("select", { "aria-label": "Sheet", onchange: () => this.showSheet(this.sheetSelect.value) },
      this.sheets.map((s) => h("option", { value: s.name, selected: s.name === this.sheetName }, s.name)));
    fill(host, h("div", { class: "grid-editor" },
      h("div", { class: "grid-toolbar" },
        this.sheets.length > 1 ? h("label", {}, "Sheet ", this.sheetSelect) : h("span", { class: "muted" }, `Sheet “${this.sheetName}”`),
        readOnly ? null : h("button", { class: "secondary", "data-testid": "grid-add-row", onclick: () => this.insertRow() }, "+ Add a row below"),
        readOnly ? null : h("button", { class: "secondary", "data-testid": "grid-delete-row", onclick: () => this.deleteRow() }, "− Remove this row"),
        this.statusEl),
      h("p", { class: "hint" }, "Each row under the table's four header rows is one rule. An empty cell leaves that condition or action out; an empty row ends the table."),
      h("div", { class: "grid-scroll" }, this.tableEl)));
    this.render();
  }

  get sheet() {
    return this.sheets.find((s) => s.name === this.sheetName) || this.sheets[0];
  }

  showSheet(name) {
    this.sheetName = name;
    this.render();
  }

  // ---- rendering ------------------------------------------------------------------------------

  render() {
    const sheet = this.sheet;
    if (!sheet) {
      fill(this.tableEl, h("tr", {}, h("td", {}, "This workbook has no sheets.")));
      return;
    }
    const rows = sheet.rows;
    const merged = (sheet.merged || []).map(parseRange).filter(Boolean);
    const width = Math.max(1, ...rows.map((r) => r.length), ...merged.map((m) => m.c2)) + 1;
    const height = rows.length + 1;
    const tables = ruleTables(rows);
    const roleOf = (r) => {
      for (const t of tables) {
        const offset = r - t.row;
        if (offset === 0) return "table-name";
        if (offset >= 1 && offset <= 4) return ["keywords", "object-types", "templates", "labels"][offset - 1];
      }
      return "";
    };
    const labels = {};
    for (const t of tables) (rows[t.row + 3] || []).forEach((text, c) => { if (text) labels[c + 1] = text; });
    const head = h("tr", {}, h("th", { class: "corner" }), Array.from({ length: width }, (_, c) => h("th", {}, cellName(1, c + 1).replace(/\d+$/, ""))));
    const body = Array.from({ length: height }, (_, r0) => {
      const r = r0 + 1;
      const role = roleOf(r);
      return h("tr", { class: role, "data-row": r },
        h("th", { class: "row-number" }, String(r)),
        Array.from({ length: width }, (_, c0) => {
          const c = c0 + 1;
          const inMerge = merged.find((m) => r >= m.r1 && r <= m.r2 && c >= m.c1 && c <= m.c2);
          const anchor = inMerge && (inMerge.r1 !== r || inMerge.c1 !== c);
          const value = anchor ? "" : ((rows[r - 1] || [])[c - 1] || "");
          const input = h("input", {
            type: "text", value, "data-cell": cellName(r, c), "aria-label": `Cell ${cellName(r, c)}`,
            title: labels[c] && !role ? labels[c] : null,
            disabled: this.readOnly || anchor,
            placeholder: anchor ? "⟵ merged" : null,
            onfocus: () => {
              this.selected = { row: r, col: c };
              this.markSelected();
              this.onSelect?.(r);
            },
            oninput: (e) => this.edit(r, c, e.target.value),
            onkeydown: (e) => this.key(e, r, c),
          });
          return h("td", { class: `${inMerge ? "merged" : ""}${anchor ? " merged-part" : ""}`, "data-cell": cellName(r, c) }, input);
        }));
    });
    fill(this.tableEl, h("thead", {}, head), h("tbody", {}, body));
    this.markProblems();
    this.markSelected();
  }

  markSelected() {
    for (const tr of this.tableEl.querySelectorAll("tr.selected")) tr.classList.remove("selected");
    const tr = this.tableEl.querySelector(`tr[data-row="${this.selected.row}"]`);
    if (tr) tr.classList.add("selected");
  }

  input(row, col) {
    return this.tableEl.querySelector(`input[data-cell="${cellName(row, col)}"]`);
  }

  key(event, row, col) {
    if (event.key === "Enter" || event.key === "ArrowDown") {
      event.preventDefault();
      this.input(row + 1, col)?.focus();
    } else if (event.key === "ArrowUp") {
      event.preventDefault();
      this.input(row - 1, col)?.focus();
    }
  }

  // ---- editing --------------------------------------------------------------------------------

  edit(row, col, value) {
    const rows = this.sheet.rows;
    while (rows.length < row) rows.push([]);
    const cells = rows[row - 1];
    while (cells.length < col) cells.push("");
    cells[col - 1] = value;
    const height = this.tableEl.querySelectorAll("tbody tr").length;
    const width = this.tableEl.querySelectorAll("thead th").length - 1;
    if (row >= height || col >= width) {
      this.render(); // typed into the spare row or column: grow the grid, keep the caret
      const input = this.input(row, col);
      input?.focus();
      input?.setSelectionRange(value.length, value.length);
    }
    this.changed();
  }

  insertRow() {
    const at = this.selected.row; // the new row goes below the selected one
    const sheet = this.sheet;
    sheet.rows.splice(at, 0, []);
    sheet.merged = (sheet.merged || []).map(parseRange).filter(Boolean).map((m) => (m.r1 > at ? { ...m, r1: m.r1 + 1, r2: m.r2 + 1 } : m.r2 > at ? { ...m, r2: m.r2 + 1 } : m)).map(rangeText);
    this.mergedChanged = true;
    this.selected = { row: at + 1, col: this.selected.col };
    this.render();
    this.input(at + 1, this.selected.col)?.focus();
    this.changed();
  }

  deleteRow() {
    const at = this.selected.row;
    const sheet = this.sheet;
    if (at > sheet.rows.length) return;
    sheet.rows.splice(at - 1, 1);
    sheet.merged = (sheet.merged || []).map(parseRange).filter(Boolean)
      .filter((m) => !(m.r1 === at && m.r2 === at))
      .map((m) => (m.r1 > at ? { ...m, r1: m.r1 - 1, r2: m.r2 - 1 } : m.r2 >= at ? { ...m, r2: m.r2 - 1 } : m)).map(rangeText);
    this.mergedChanged = true;
    this.render();
    this.input(Math.min(at, sheet.rows.length), this.selected.col)?.focus();
    this.changed();
  }

  changed() {
    fill(this.statusEl, "Saving the table…");
    this.statusEl.className = "grid-status pending";
    this.dirty = true;
    this.scheduleWrite();
  }

  /** Write the grid into the file through the gateway; the newest write wins. */
  async write() {
    const seq = ++this.writeSeq;
    const sheet = this.sheet;
    const body = { file: this.fileName, content: this.text, sheet: sheet.name, rows: sheet.rows };
    if (this.mergedChanged) body.merged = sheet.merged;
    this.dirty = false;
    this.pending = (async () => {
      try {
        const result = await api("POST", "/api/decision-tables/write", body);
        if (seq !== this.writeSeq) return;
        this.text = result.content;
        this.mergedChanged = false;
        this.statusEl.className = "grid-status ok";
        fill(this.statusEl, "✓ Saved in the file (not deployed)");
        this.onChange(this.text);
      } catch (err) {
        if (seq !== this.writeSeq) return;
        this.statusEl.className = "grid-status error";
        fill(this.statusEl, `Could not write the table: ${err.message}`);
      }
    })();
    await this.pending;
  }

  /** The file's text with every edit so far. */
  content() {
    return this.text;
  }

  /** Wait until every edit is in content(). */
  async flush() {
    if (this.dirty) {
      this.scheduleWrite.cancel();
      await this.write();
    } else if (this.pending) await this.pending;
  }

  /** Replace the whole file (e.g. "undo all my changes"). */
  async setContent(text) {
    this.scheduleWrite.cancel();
    this.writeSeq++;
    this.dirty = false;
    const grid = await api("POST", "/api/decision-tables/read", { file: this.fileName, content: text });
    this.text = text;
    this.sheets = grid.sheets;
    this.render();
    this.onChange(this.text);
  }

  // ---- problems -------------------------------------------------------------------------------

  /** Mark the cells problems name ({sheet, cell, line, column, message}). */
  showProblems(problems) {
    this.problems = problems;
    this.markProblems();
  }

  markProblems() {
    for (const td of this.tableEl.querySelectorAll("td.problem")) {
      td.classList.remove("problem", "error", "warning");
      td.querySelector("input")?.removeAttribute("data-problem");
    }
    for (const p of this.problems) {
      if (p.sheet && p.sheet !== this.sheetName) continue;
      const name = p.cell || (p.line > 0 && p.column > 0 ? cellName(p.line, p.column) : "");
      const td = name && this.tableEl.querySelector(`td[data-cell="${name}"]`);
      if (!td) continue;
      td.classList.add("problem", p.severity === "warning" ? "warning" : "error");
      const input = td.querySelector("input");
      input.setAttribute("data-problem", p.message);
      input.title = p.message;
    }
  }

  /** Show a problem's cell and put the caret in it. */
  reveal(problem) {
    if (problem.sheet && problem.sheet !== this.sheetName && this.sheets.some((s) => s.name === problem.sheet)) {
      this.sheetSelect.value = problem.sheet;
      this.showSheet(problem.sheet);
    }
    const input = problem.cell ? this.tableEl.querySelector(`input[data-cell="${problem.cell}"]`) : this.input(problem.line, problem.column);
    if (input) {
      input.scrollIntoView({ block: "center", inline: "center" });
      input.focus();
    }
  }

  requestMeasure() {}

  dispose() {
    this.scheduleWrite.cancel();
  }
}
