// The main view: a rule set's files in editors, checked as you type, with the DRL preview, the
// "Try it" panel and Deploy. Edits are kept as a local draft (localStorage) until deployed, so a
// reload, a conflict or a closed tab loses nothing. The rule list and search, the tests panel, Try it
// and Deploy are methods of this view written in their own modules (rules-search.js,
// rules-tests-panel.js, rules-try.js, rules-deploy.js).

import { api, rulesetPath } from "./api.js";
import { localProblems } from "./checks.js";
import { h, fill, when, debounce } from "./dom.js";
import { assistFor, declaredTypes, dslEntries } from "./dsl-assist.js";
import { createEditor, setText, showProblems, reveal, scrollToLine } from "./editor.js";
import { findHighlight } from "./find-highlight.js";
import { reachBar } from "./reach-bar.js";
import { normalizeErrors, draftKey } from "./rules-common.js";
import { mountTableEditor } from "./table-editor.js";
import { searchMethods } from "./rules-search.js";
import { testsPanelMethods } from "./rules-tests-panel.js";
import { tryMethods } from "./rules-try.js";
import { deployMethods } from "./rules-deploy.js";

const CHECK_DELAY_MS = 500;
const ADDABLE = [".xlsx", ".csv", ".dslr", ".dsl", ".drl"];
const MAX_ADDED_BYTES = 1024 * 1024;
const XLSX_TYPE = "application/vnd.openxmlformats-officedocument.spreadsheetml.sheet";

/** A workbook as the REST API carries it: a base64 data: URL of the spreadsheet type. */
function readAsDataUrl(file, type) {
  return new Promise((resolve, reject) => {
    const reader = new FileReader();
    reader.onload = () => resolve(`data:${type};base64,${String(reader.result).split(",")[1] || ""}`);
    reader.onerror = () => reject(reader.error);
    reader.readAsDataURL(file);
  });
}

const KINDS = [
  [".dslr", "rules in plain sentences"],
  [".xlsx", "decision table"],
  [".csv", "decision table"],
  [".dsl", "sentence dictionary"],
  [".drl", "rules (technical)"],
  [".json", "examples"],
  [".yaml", "tests"],
  [".yml", "tests"],
];

function isTable(fileName) {
  return /\.(csv|xlsx)$/i.test(fileName);
}

/** Where a problem is, in words: "greetings.xlsx, cell Greetings!C7" or "x.dslr, line 3, column 5". */
function problemWhere(p) {
  if (p.cell) return `${p.file}, cell ${p.sheet ? `${p.sheet}!` : ""}${p.cell}`;
  return `${p.file || "rule set"}${p.line ? `, line ${p.line}` : ""}${p.column ? `, column ${p.column}` : ""}`;
}

function kindOf(fileName) {
  const lower = fileName.toLowerCase();
  const index = KINDS.findIndex(([ext]) => lower.endsWith(ext));
  return index < 0 ? { order: KINDS.length, label: "file" } : { order: index, label: KINDS[index][1] };
}

/** File names in the order a non-programmer should meet them: sentences first. */
export function orderedFiles(names) {
  return [...names].sort((a, b) => kindOf(a).order - kindOf(b).order || a.localeCompare(b));
}

function sameFiles(a, b) {
  const keys = Object.keys(a);
  return keys.length === Object.keys(b).length && keys.every((k) => a[k] === b[k]);
}

/** Open rule set `name` in `main`; returns the view (with dispose()) or null when it failed. */
export async function showRules(main, ctx, name) {
  fill(main, h("p", { class: "muted" }, `Opening “${name}”…`));
  let current;
  try {
    current = await api("GET", rulesetPath(name));
  } catch (err) {
    fill(main, h("div", { class: "message error", role: "alert" }, `Cannot open the rule set “${name}”: ${err.message}`));
    return null;
  }
  const [types, examples] = await Promise.all([
    api("GET", rulesetPath(name, "/types")).catch(() => ({})),
    api("GET", rulesetPath(name, "/examples")).catch(() => []),
  ]);
  return new RulesView(main, ctx, current, types || {}, Array.isArray(examples) ? examples : []);
}

class RulesView {
  constructor(main, ctx, current, types, examples) {
    this.ctx = ctx;
    this.info = current.info || current;
    this.name = this.info.name;
    this.base = this.info.version;
    this.original = { ...(current.files || {}) };
    this.types = types;
    this.examples = examples;
    this.editable = ctx.isAuthor();
    this.views = {};
    this.tables = {}; // decision tables: file name -> grid editor (once mounted)
    this.tableTexts = {}; // decision tables: file name -> the file's current text
    this.hosts = {};
    this.tabs = {};
    this.local = [];
    this.server = [];
    this.checkError = "";
    this.seq = 0;
    this.previewOn = false;
    this.scheduleCheck = debounce(() => this.check(), CHECK_DELAY_MS);
    this.saveDraft = debounce(() => this.storeDraft(), 300);
    this.build(main);
    const draft = this.loadDraft();
    this.active = orderedFiles(Object.keys(draft ? draft.files : this.original))[0];
    this.createEditors(draft ? draft.files : this.original);
    this.ruleList.load();
    if (draft) this.announceDraft(draft);
    this.select(this.active);
    this.updateDirty();
    this.check();
  }

  dispose() {
    this.disposed = true; // stops following a build job (the build itself goes on; see Build jobs)
    this.jobsList.dispose();
    this.scheduleCheck.cancel();
    this.saveDraft.cancel();
    this.storeDraft();
    this.seq++;
    this.testsView?.dispose();
    this.ruleList?.dispose();
    for (const table of Object.values(this.tables)) table.dispose();
  }

  /** The rule set's sentences and fact types as being edited (for completion and hover). */
  assistSource() {
    if (!this.assistCache) {
      const files = this.files();
      this.assistCache = { entries: dslEntries(files), types: declaredTypes(files, this.types) };
    }
    return this.assistCache;
  }

  /** Wait until every decision-table edit is written into its file. */
  async flushTables() {
    await Promise.all(Object.values(this.tables).map((t) => t.flush()));
  }

  // ---- layout -------------------------------------------------------------------------------

  build(main) {
    this.liveEl = h("span", { class: "live", "data-testid": "live-version" });
    this.dirtyEl = h("span", { class: "badge dirty", hidden: true }, "Changed — not deployed yet");
    this.bannerEl = h("div", { class: "banners" });
    this.tabsEl = h("div", { class: "tabs", role: "tablist" });
    this.statusEl = h("span", { class: "check-status", "data-testid": "check-status", "aria-live": "polite" });
    this.previewToggle = h("input", { type: "checkbox", onchange: () => this.togglePreview() });
    this.editorsEl = h("div", { class: "editors" });
    this.previewTitle = h("div", { class: "pane-title" });
    this.previewHost = h("div", { class: "preview-host" });
    this.previewEl = h("div", { class: "preview", hidden: true, "data-testid": "preview" }, this.previewTitle, this.previewHost);
    this.problemsEl = h("ul", { class: "problems", "data-testid": "problems" });
    this.previewView = createEditor(this.previewHost, { doc: "", fileName: "preview.drl", readOnly: true, label: "Generated DRL" });

    fill(main, h("section", { class: "ruleset" },
      h("div", { class: "title-row" }, h("h1", {}, this.name), this.liveEl, this.dirtyEl),
      this.bannerEl,
      this.editable ? null : h("div", { class: "message info" },
        "You are signed in with a caller token: you can read and try the rules, but not change or deploy them."),
      h("div", { class: "columns" },
        h("div", { class: "left" },
          ...this.buildRuleListAndTools(),
          h("div", { class: "toolbar" }, this.tabsEl, this.buildAddFile(),
            h("label", { class: "toggle" }, this.previewToggle, " Show the DRL it becomes"),
            this.statusEl),
          h("div", { class: "editor-area" }, this.editorsEl, this.previewEl),
          h("h2", { class: "small" }, "Problems"), this.problemsEl),
        h("div", { class: "right" }, this.buildDeploy(), this.buildJobs(), this.buildTry(), this.buildTests())),
      reachBar([
        { label: "▶ Try it", testid: "reach-try", target: () => main.querySelector(".card.try") },
        this.editable ? { label: "Deploy…", testid: "reach-deploy", target: () => main.querySelector(".card.deploy"),
          then: () => this.commentEl.focus({ preventScroll: true }) } : null,
      ].filter(Boolean))));
    this.renderLive();
  }

  renderLive() {
    const i = this.info;
    fill(this.liveEl, `Live: version ${i.version}`, i.author ? ` · by ${i.author}` : "", ` · ${when(i.deployed_at)}`);
  }

  createEditors(files) {
    for (const fileName of orderedFiles(Object.keys(files))) {
      const host = h("div", { class: "editor-host", hidden: true, "data-file": fileName });
      this.editorsEl.append(host);
      this.hosts[fileName] = host;
      if (isTable(fileName)) this.createTable(host, fileName, files[fileName]);
      else this.views[fileName] = createEditor(host, {
        doc: files[fileName], fileName, readOnly: !this.editable,
        label: `Editor for ${fileName}`, onChange: () => this.changed(), onCursor: (line) => this.followCursor(fileName, line),
        extensions: [assistFor(fileName, () => this.assistSource()), findHighlight()],
      });
      const tab = h("button", { class: "tab", role: "tab", "data-file": fileName, onclick: () => this.select(fileName) },
        h("span", { class: "tab-name" }, fileName), h("span", { class: "tab-kind" }, kindOf(fileName).label),
        h("span", { class: "tab-count" }));
      this.tabs[fileName] = tab;
      this.tabsEl.append(tab);
    }
  }

  /** A decision table opens as a grid (mounted once the gateway has read the file). */
  createTable(host, fileName, text) {
    host.classList.add("table-host");
    this.tableTexts[fileName] = text;
    fill(host, h("p", { class: "muted" }, `Opening the table ${fileName}…`));
    mountTableEditor(host, {
      fileName, content: text, readOnly: !this.editable,
      onChange: (content) => {
        this.tableTexts[fileName] = content;
        this.changed();
      },
      onSelect: (row) => this.followTableRow(fileName, row),
    }).then((editor) => {
      this.tables[fileName] = editor;
      editor.showProblems(this.allProblems().filter((p) => p.file === fileName));
    }).catch((err) => {
      fill(host, h("div", { class: "message error", role: "alert" }, `Cannot open ${fileName} as a table: ${err.message}`));
    });
  }

  select(fileName) {
    this.active = fileName;
    const view = this.views[fileName];
    this.cursorLine = view ? view.state.doc.lineAt(view.state.selection.main.head).number : 1;
    for (const [name, host] of Object.entries(this.hosts)) host.hidden = name !== fileName;
    for (const [name, tab] of Object.entries(this.tabs)) tab.setAttribute("aria-selected", String(name === fileName));
    this.views[fileName]?.requestMeasure();
    this.renderPreview();
  }

  files() {
    const files = {};
    for (const [name, view] of Object.entries(this.views)) files[name] = view.state.doc.toString();
    for (const [name, text] of Object.entries(this.tableTexts)) files[name] = text;
    return files;
  }

  changed() {
    this.assistCache = null;
    this.replay?.reset(); // a replay says what the text it replayed does, not this one
    this.testsView?.markStale();
    this.ruleList?.refresh();
    this.updateDirty();
    this.saveDraft();
    this.statusEl.className = "check-status pending";
    fill(this.statusEl, "Checking…");
    this.scheduleCheck();
  }

  updateDirty() {
    this.dirtyEl.hidden = sameFiles(this.files(), this.original);
  }

  // ---- drafts ---------------------------------------------------------------------------------

  loadDraft() {
    if (!this.editable) return null;
    try {
      const draft = JSON.parse(localStorage.getItem(draftKey(this.name)) || "null");
      if (!draft || typeof draft.files !== "object" || sameFiles(draft.files, this.original)) return null;
      if (draft.base !== this.info.version) this.base = draft.base;
      return draft;
    } catch {
      return null;
    }
  }

  storeDraft() {
    if (!this.editable) return;
    const files = this.files();
    try {
      if (sameFiles(files, this.original)) localStorage.removeItem(draftKey(this.name));
      else localStorage.setItem(draftKey(this.name), JSON.stringify({ base: this.base, files, saved_at: new Date().toISOString() }));
    } catch {
      this.banner("warning", "These files are too big to keep a local copy in the browser: deploy or keep the tab open.");
    }
  }

  announceDraft(draft) {
    const parts = [`Your changes from ${when(draft.saved_at)} are back (they were not deployed).`];
    if (draft.base !== this.info.version) {
      parts.push(` You started from version ${draft.base}; version ${this.info.version} has been deployed since.`);
    }
    this.banner("info", parts.join(""), h("button", { class: "link", onclick: (e) => {
      e.target.closest(".message").remove();
      this.discard();
    } }, "Throw my changes away"));
  }

  banner(kind, text, ...extra) {
    this.bannerEl.append(h("div", { class: `message ${kind}`, role: kind === "error" ? "alert" : "status" }, text, " ", extra));
  }

  discard() {
    for (const [name, view] of Object.entries(this.views)) {
      if (name in this.original && view.state.doc.toString() !== this.original[name]) setText(view, this.original[name]);
    }
    for (const [name, table] of Object.entries(this.tables)) {
      if (name in this.original && this.tableTexts[name] !== this.original[name]) table.setContent(this.original[name]);
    }
    this.base = this.info.version;
    localStorage.removeItem(draftKey(this.name));
  }

  // ---- checking -------------------------------------------------------------------------------

  async check() {
    const seq = ++this.seq;
    await this.flushTables();
    if (seq !== this.seq) return;
    const files = this.files();
    this.local = localProblems(files);
    this.renderProblems(true);
    try {
      const result = await api("POST", rulesetPath(this.name, "/validate"), { files });
      if (seq !== this.seq) return;
      this.server = normalizeErrors(result && result.errors);
      this.checkError = "";
    } catch (err) {
      if (seq !== this.seq) return;
      this.server = normalizeErrors(err.errors);
      this.checkError = this.server.length || err.status === 403 ? "" : err.message;
    }
    this.renderProblems(false);
    if (this.previewOn) await this.expand(seq, files);
  }

  allProblems() {
    const order = orderedFiles(Object.keys(this.views));
    const rank = (p) => (order.includes(p.file) ? order.indexOf(p.file) : -1);
    // The server's compiler knows best: drop a browser-side note on a line it already reported.
    const reported = new Set(this.server.map((p) => `${p.file}:${p.line}`));
    const local = this.local.filter((p) => !reported.has(`${p.file}:${p.line}`));
    // ...but keeps the browser's quick fixes for the line (the nearest known sentences).
    const fixes = new Map(this.local.filter((p) => p.fixes && p.fixes.length).map((p) => [`${p.file}:${p.line}`, p.fixes]));
    const server = this.server.map((p) => (fixes.has(`${p.file}:${p.line}`) && !p.cell ? { ...p, fixes: fixes.get(`${p.file}:${p.line}`) } : p));
    return [...server, ...local].sort((a, b) => rank(a) - rank(b) || a.line - b.line || a.column - b.column);
  }

  renderProblems(pending) {
    const problems = this.allProblems();
    for (const name of Object.keys(this.tabs)) {
      const mine = problems.filter((p) => p.file === name);
      if (this.views[name]) showProblems(this.views[name], mine);
      else this.tables[name]?.showProblems(mine);
      const count = this.tabs[name].querySelector(".tab-count");
      count.textContent = mine.length ? String(mine.length) : "";
      count.className = `tab-count${mine.some((p) => p.severity === "error") ? " error" : mine.length ? " warning" : ""}`;
    }
    fill(this.problemsEl, problems.map((p) => h("li", { class: p.severity },
      h("button", { class: "problem", onclick: () => this.goTo(p) },
        h("span", { class: "where" }, problemWhere(p)),
        h("span", { class: "what" }, p.message)))));
    const errors = problems.filter((p) => p.severity === "error").length;
    const warnings = problems.length - errors;
    let text;
    let kind;
    if (pending) [text, kind] = ["Checking…", "pending"];
    else if (this.checkError) [text, kind] = [`Could not check: ${this.checkError}`, "error"];
    else if (errors) [text, kind] = [`✗ ${plural(errors, "problem")}${warnings ? `, ${plural(warnings, "warning")}` : ""}`, "error"];
    else if (warnings) [text, kind] = [`⚠ ${plural(warnings, "warning")}`, "warning"];
    else [text, kind] = ["✓ No problems", "ok"];
    this.statusEl.className = `check-status ${kind}`;
    this.statusEl.textContent = text;
    if (!problems.length) this.problemsEl.append(h("li", { class: "none" }, pending ? "Checking…" : "None."));
  }

  goTo(problem) {
    if (this.tables[problem.file]) {
      this.select(problem.file);
      this.tables[problem.file].reveal(problem);
      return;
    }
    if (!this.views[problem.file]) return;
    this.select(problem.file);
    if (problem.line > 0) reveal(this.views[problem.file], problem);
  }

  // ---- DRL preview ----------------------------------------------------------------------------

  togglePreview() {
    this.previewOn = this.previewToggle.checked;
    this.previewEl.hidden = !this.previewOn;
    this.editorsEl.parentElement.classList.toggle("split", this.previewOn);
    if (this.previewOn) this.expand(this.seq, this.files());
  }

  async expand(seq, files) {
    try {
      const result = await api("POST", rulesetPath(this.name, "/expand"), { files });
      if (seq !== this.seq) return;
      this.expanded = (result && (result.expanded || result.files)) || {};
      this.expandError = "";
    } catch (err) {
      if (seq !== this.seq) return;
      this.expandError = err.message; // keep showing the last good expansion below the note
    }
    this.renderPreview();
  }

  renderPreview() {
    if (!this.previewOn) return;
    const isDslr = this.active.toLowerCase().endsWith(".dslr") || isTable(this.active);
    let text = "";
    if (!isDslr) {
      this.previewTitle.textContent = `${this.active} is not a .dslr file or a decision table: there is nothing to expand.`;
    } else if (this.expandError) {
      this.previewTitle.textContent = `Cannot expand the current text (${this.expandError}). Showing the last good expansion.`;
      text = (this.expanded && this.expanded[this.active]) || "";
    } else {
      this.previewTitle.textContent = `What the rule engine reads for ${this.active} (generated, read-only)`;
      text = (this.expanded && this.expanded[this.active]) || "";
    }
    if (this.previewView.state.doc.toString() !== text) setText(this.previewView, text);
    if (isTable(this.active)) this.followTableRow(this.active, this.tableRow || 1);
    else if (isDslr) this.followCursor(this.active, this.cursorLine || 1);
  }

  /** Keep the rule a table's selected row becomes in view ("// RuleTable … , row N" heads it). */
  followTableRow(fileName, row) {
    this.tableRow = row;
    if (!this.previewOn || fileName !== this.active) return;
    const doc = this.previewView.state.doc;
    for (let n = 1; n <= doc.lines; n++) {
      if (doc.line(n).text.endsWith(`, row ${row}`)) {
        scrollToLine(this.previewView, n, "start");
        return;
      }
    }
  }

  /** Keep the generated DRL of the rule being edited in view. Expansion does not keep line
   * numbers (constraint lines join their pattern), so the rule's header is what is matched. */
  followCursor(fileName, line) {
    this.cursorLine = line;
    if (!this.previewOn || fileName !== this.active || !fileName.toLowerCase().endsWith(".dslr")) return;
    const header = ruleHeaderAbove(this.views[fileName].state.doc, line);
    const target = header ? findLine(this.previewView.state.doc, header) : 0;
    scrollToLine(this.previewView, target || line, target ? "start" : "center");
  }

  // ---- Adding a file ---------------------------------------------------------------------------

  /** "Add a file": a spreadsheet decision table (.xlsx/.csv) or a rule file from the user's computer,
   * added to the draft as a new tab (deployed with the rest); nothing is sent until Deploy. */
  buildAddFile() {
    if (!this.editable) return null;
    this.addResultEl = h("span", { class: "add-file-result", "data-testid": "add-file-result", "aria-live": "polite" });
    const input = h("input", { type: "file", class: "visually-hidden", "data-testid": "add-file",
      accept: ADDABLE.join(","), "aria-label": "Add a file to the rule set",
      onchange: async () => {
        const file = input.files[0];
        input.value = "";
        if (file) fill(this.addResultEl, await this.addFile(file));
      } });
    return h("span", { class: "add-file" },
      h("button", { class: "secondary", type: "button", onclick: () => input.click() }, "+ Add a file…"), input, this.addResultEl);
  }

  /** Read `file` into the draft; the message says what happened or what is wrong with the file. */
  async addFile(file) {
    const name = file.name;
    const lower = name.toLowerCase();
    const fail = (text) => h("span", { class: "message error inline", role: "alert" }, text);
    if (!ADDABLE.some((ext) => lower.endsWith(ext))) return fail(`${name}: only ${ADDABLE.join(", ")} files can be added.`);
    if (!/^[A-Za-z0-9._-]+$/.test(name)) return fail(`${name}: a file name may hold only letters, digits, '.', '_' and '-'.`);
    if (file.size > MAX_ADDED_BYTES) return fail(`${name}: ${Math.round(file.size / 1024)} KB is more than the ${MAX_ADDED_BYTES / 1024} KB allowed.`);
    if (this.hosts[name]) return fail(`${name}: the rule set already has a file of that name; edit its tab or rename the file.`);
    let content;
    try {
      content = lower.endsWith(".xlsx") ? await readAsDataUrl(file, XLSX_TYPE) : await file.text();
    } catch (err) {
      return fail(`${name}: cannot be read (${err.message || err}).`);
    }
    if (!lower.endsWith(".xlsx") && content.includes("\u0000")) return fail(`${name}: is not a text file.`);
    this.createEditors({ [name]: content });
    this.select(name);
    this.changed();
    return h("span", { class: "message ok inline", role: "status" }, `Added ${name}: check it, then deploy.`);
  }
}

// The rule list and search, the tests panel, Try it and Deploy are the view's methods too, each in its module.
Object.assign(RulesView.prototype, searchMethods, testsPanelMethods, tryMethods, deployMethods);

/** The "rule ..." line of the rule that contains line `number` (trimmed), or "". */
function ruleHeaderAbove(doc, number) {
  for (let n = Math.min(number, doc.lines); n >= 1; n--) {
    const text = doc.line(n).text.trim();
    if (/^rule\s/.test(text)) return text;
    if (n < number && text === "end") return "";
  }
  return "";
}

/** 1-based number of the first line whose trimmed text is `text` (0 when none). */
function findLine(doc, text) {
  for (let n = 1; n <= doc.lines; n++) if (doc.line(n).text.trim() === text) return n;
  return 0;
}

function plural(n, word) {
  return `${n} ${word}${n > 1 ? "s" : ""}`;
}
