// The main view: a rule set's files in editors, checked as you type, with the DRL preview, the
// "Try it" panel and Deploy. Edits are kept as a local draft (localStorage) until deployed, so a
// reload, a conflict or a closed tab loses nothing.

import { h, fill, when, debounce } from "./dom.js";
import { api, rulesetPath } from "./api.js";
import { createEditor, setText, showProblems, reveal, scrollToLine } from "./editor.js";
import { localProblems } from "./checks.js";
import { actionList, firedList } from "./actions.js";
import { assistFor, declaredTypes, dslEntries } from "./dsl-assist.js";
import { mountTests } from "./tests-view.js";
import { offerTestUpdate } from "./tests-update.js";
import { mountRuleList } from "./rule-list.js";
import { findHighlight, setFind } from "./find-highlight.js";
import { mountRuleTools } from "./rule-tools.js";
import { reachBar } from "./reach-bar.js";
import { mountTableEditor } from "./table-editor.js";
import { FollowStopped, deployOutcome, followJob, isCancelled, isJob, submitJob } from "./jobs.js";
import { JobProgress, JobsList } from "./jobs-view.js";
import { WhatWouldChange } from "./replay-panel.js";

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

function draftKey(name) {
  return `printeps.workbench.draft.${name}`;
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

  // ---- Try it ---------------------------------------------------------------------------------

  buildTry() {
    this.tryResultEl = h("div", { class: "try-result", "data-testid": "try-result", "aria-live": "polite" });
    const factsHost = h("div", { class: "facts-host" });
    const initial = this.examples.length ? this.examples[0].facts : [];
    this.factsView = createEditor(factsHost, { doc: JSON.stringify(initial, null, 2), fileName: "facts.json", label: "Facts (JSON)" });
    const exampleButtons = this.examples.map((ex) => h("button", {
      class: "chip", onclick: () => setText(this.factsView, JSON.stringify(ex.facts, null, 2)),
    }, ex.name));
    const typeButtons = Object.keys(this.types).sort().map((type) => h("button", {
      class: "chip add", title: `Fields: ${Object.entries(this.types[type]).map(([f, t]) => `${f} (${t})`).join(", ")}`,
      onclick: () => this.addFact(type),
    }, `+ ${type}`));
    return h("div", { class: "card try" },
      h("h2", {}, "Try it"),
      h("p", { class: "hint" }, "Pick a situation (or write facts), then press Try it. It uses the text in the editor; nothing is deployed."),
      exampleButtons.length ? h("div", { class: "chips" }, h("span", { class: "label" }, "Situations:"), exampleButtons) : null,
      typeButtons.length ? h("div", { class: "chips" }, h("span", { class: "label" }, "Add a fact:"), typeButtons) : null,
      factsHost,
      h("button", { class: "big primary", "data-testid": "try", onclick: () => this.tryIt() }, "▶ Try it"),
      this.tryResultEl);
  }

  addFact(type) {
    const template = { type };
    for (const [field, javaType] of Object.entries(this.types[type] || {})) template[field] = sampleValue(field, javaType);
    let facts;
    try {
      facts = JSON.parse(this.factsView.state.doc.toString() || "[]");
    } catch {
      facts = null;
    }
    if (!Array.isArray(facts)) facts = facts && typeof facts === "object" ? [facts] : [];
    facts.push(template);
    setText(this.factsView, JSON.stringify(facts, null, 2));
  }

  async tryIt() {
    await this.flushTables();
    const text = this.factsView.state.doc.toString();
    let facts;
    try {
      facts = JSON.parse(text.trim() || "[]");
    } catch (err) {
      fill(this.tryResultEl, h("div", { class: "message error", role: "alert" }, `The facts are not valid JSON: ${jsonErrorWhere(text, err)}`));
      return;
    }
    if (!Array.isArray(facts)) facts = [facts];
    fill(this.tryResultEl, h("p", { class: "muted" }, "Trying…"));
    try {
      const result = await api("POST", rulesetPath(this.name, "/try"), { files: this.files(), facts });
      fill(this.tryResultEl,
        h("h3", {}, "The robot would:"), actionList(result.actions),
        h("h3", {}, "Rules that fired, in order:"), firedList(result.fired),
        h("details", {}, h("summary", {}, "Facts afterwards"), h("pre", {}, JSON.stringify(result.facts || [], null, 2))));
    } catch (err) {
      const compile = normalizeErrors(err.errors.filter((e) => e.file !== undefined || e.line !== undefined));
      const factErrors = err.errors.filter((e) => e.file === undefined && e.line === undefined);
      if (compile.length) {
        this.server = compile;
        this.renderProblems(false);
      }
      fill(this.tryResultEl, h("div", { class: "message error", role: "alert" },
        compile.length ? "The rules have problems (see the list under the editor): fix them and try again." : err.message,
        factErrors.length ? h("ul", {}, factErrors.map((e) => h("li", {}, describeFactError(e)))) : null));
    }
  }

  // ---- Deploy ---------------------------------------------------------------------------------

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

  buildDeploy() {
    if (!this.editable) return null;
    this.commentEl = h("input", { type: "text", class: "comment", maxlength: "500", "aria-label": "What did you change?",
      placeholder: "e.g. Friendlier greeting for groups" });
    this.deployResultEl = h("div", { class: "deploy-result", "data-testid": "deploy-result", "aria-live": "polite" });
    this.deployButton = h("button", { class: "big primary", "data-testid": "deploy", onclick: () => this.deploy() }, "Deploy to the robot");
    this.replay = new WhatWouldChange(this.ctx, this.name, async () => {
      await this.flushTables();
      return this.files();
    });
    return h("div", { class: "card deploy" },
      h("h2", {}, "Deploy"),
      h("label", { class: "field" }, "What did you change? (shown in the history)", this.commentEl),
      h("div", { class: "buttons" },
        this.replay.button,
        this.deployButton,
        h("button", { class: "big secondary", onclick: () => this.discard() }, "Undo all my changes")),
      this.replay.el,
      this.deployResultEl);
  }

  /** The rule set's recent build jobs (collapsed until wanted). */
  buildJobs() {
    this.jobsList = new JobsList({ ruleset: this.name, editable: this.editable });
    return this.jobsList.el;
  }

  // ---- The rules as a list ----------------------------------------------------------------------

  /** The rule list, and under it (authors) the panels of its Replace… and + New rule buttons. */
  buildRuleListAndTools() {
    const host = h("div", { class: "rule-list-host" });
    const tools = this.editable ? this.buildRuleTools() : null;
    this.ruleList = mountRuleList(host, {
      name: this.name,
      files: () => this.files(),
      goTo: (rule) => this.goTo(rule.row ? { file: rule.file, line: rule.row, column: 1, sheet: rule.sheet } : { file: rule.file, line: rule.line, column: 1 }),
      onSearch: (text) => this.searchEditors(text),
      tools: tools ? tools.buttons : null,
    });
    return [host, tools ? tools.host : null];
  }

  /** Replace… and + New rule: change words in every rule, or write a rule from chosen sentences. */
  buildRuleTools() {
    const host = h("div", { class: "rule-tools-host" });
    const tools = mountRuleTools(host, {
      files: () => this.files(),
      rules: () => this.ruleList.all(),
      replace: (file, changes) => this.views[file]?.dispatch({ changes }),
      append: (file, text) => {
        const view = this.views[file];
        const end = view.state.doc.length;
        const gap = end && view.state.doc.sliceString(end - 1) !== "\n" ? "\n" : "";
        view.dispatch({ changes: { from: end, insert: gap + text } });
        return view.state.doc.lineAt(end + gap.length + text.indexOf("rule ")).number;
      },
      goTo: (file, line) => this.goTo({ file, line, column: 1 }),
    });
    return { host, buttons: tools.buttons };
  }

  /** Mark the search words in every editor and bring the first rule that matches into view. */
  searchEditors(text) {
    for (const view of Object.values(this.views)) setFind(view, text);
    if (!text || !this.ruleList) return;
    const first = this.ruleList.visible().find((r) => r.line && this.views[r.file]);
    if (!first) return;
    if (first.file !== this.active) this.select(first.file);
    scrollToLine(this.views[first.file], first.line, "start");
  }

  // ---- Tests ------------------------------------------------------------------------------------

  buildTests() {
    const host = h("div", { class: "tests-host" });
    this.testsView = mountTests(host, {
      name: this.name,
      files: async () => {
        await this.flushTables();
        return this.files();
      },
      goTo: (file, line) => this.goTo({ file, line, column: 1 }),
      onErrors: (errors) => {
        this.server = normalizeErrors(errors);
        this.renderProblems(false);
      },
    });
    return host;
  }

  // ---- Deploy ---------------------------------------------------------------------------------

  async deploy(force = false) {
    if (this.building) return; // one build at a time from this page (the button is disabled meanwhile)
    this.setBuilding(true);
    fill(this.deployResultEl, h("p", { class: "muted" }, "Deploying…"));
    try {
      await this.flushTables();
      const files = this.files();
      const comment = this.replay ? this.replay.comment(this.commentEl.value.trim()) : this.commentEl.value.trim();
      if (comment === null) {
        fill(this.deployResultEl, h("div", { class: "message error", role: "alert", "data-testid": "replay-comment-needed" },
          `Your change would change ${this.replay.result.changed} recent decisions: say what you changed and why in the comment, then deploy.`));
        this.commentEl.focus();
        return;
      }
      const body = { files, comment, base_version: this.base };
      if (force) body.force = true;
      this.deployed(files, comment, await this.buildAndDeploy(body));
    } catch (err) {
      this.notDeployed(err);
    } finally {
      this.setBuilding(false);
    }
  }

  /** While a build runs the Deploy button rests, and the result area is busy (screen readers then
   * announce its end, not every step of the progress). */
  setBuilding(on) {
    this.building = on;
    this.deployButton.disabled = on;
    if (on) this.deployResultEl.setAttribute("aria-busy", "true");
    else this.deployResultEl.removeAttribute("aria-busy");
  }

  /** Deploy `body` through a build job: its progress shows while it builds (after a moment, so a
   * quick one flashes no bar) and its end becomes what the synchronous deploy answered or threw. */
  async buildAndDeploy(body) {
    this.progress = null;
    const job = await submitJob("PUT", rulesetPath(this.name), body);
    if (!isJob(job)) return job; // a gateway that deployed at once
    const progress = new JobProgress(this.deployResultEl, job);
    this.progress = progress;
    this.jobsList.refresh();
    try {
      const done = await followJob(job, { onUpdate: (j) => progress.update(j), stopped: () => this.disposed });
      return deployOutcome(done);
    } finally {
      progress.dispose();
      this.jobsList.refresh();
    }
  }

  /** The new version is live: the editor's text is now the deployed one. */
  deployed(files, comment, result) {
    this.original = files;
    this.base = result.version;
    this.info = { ...this.info, version: result.version, author: this.ctx.user?.name, comment, deployed_at: new Date().toISOString() };
    localStorage.removeItem(draftKey(this.name));
    this.commentEl.value = "";
    this.replay?.reset();
    this.renderLive();
    this.updateDirty();
    fill(this.deployResultEl, h("div", { class: "message ok", role: "status" }, `✓ Deployed. Version ${result.version} is now live.`),
      this.progress?.cancelRequested ? h("p", { class: "hint" }, "The build was too far along to cancel, so it finished.") : null);
    this.ctx.refreshRulesets();
  }

  /** Say why nothing was deployed: compile problems go under the editor, red scenarios and
   * conflicts get their own choices, a cancelled build keeps the edits. */
  notDeployed(err) {
    if (err instanceof FollowStopped) return; // the view was closed while the build ran
    if (isCancelled(err)) this.buildCancelled(err);
    else if (err.body && err.body.kind === "untracked") this.lostTrack(err);
    else if (err.status === 409) this.conflict(err.body && err.body.current);
    else if (err.body && err.body.kind === "scenarios") this.redScenarios(err.body);
    else if (err.errors && err.errors.length) {
      this.server = normalizeErrors(err.errors);
      this.renderProblems(false);
      fill(this.deployResultEl, h("div", { class: "message error", role: "alert" }, err.body && err.body.kind === "policy"
        ? `Not deployed: the rule policy refuses ${this.server.length} place(s) for your role (listed under the editor): `
          + "an author's rules may use the rule set's own types, its actions and insert/modify/update/delete, not other "
          + "Java. A developer may deploy such rules. Nothing was changed."
        : `Not deployed: fix the ${this.server.length} problem(s) listed under the editor first. Nothing was changed.`));
    } else fill(this.deployResultEl, h("div", { class: "message error", role: "alert" }, `Not deployed: ${err.message}`));
  }

  buildCancelled(err) {
    const why = /^cancelled\b/.test(err.message) ? err.message : `cancelled (${err.message})`; // "cancelled by alice"
    fill(this.deployResultEl, h("div", { class: "message info", role: "status", "data-testid": "build-cancelled" },
      `Not deployed: the build was ${why}. Nothing was changed; your changes are still here.`));
  }

  /** Following the job failed (the gateway stopped answering): the build may still end either way. */
  lostTrack(err) {
    fill(this.deployResultEl, h("div", { class: "message warning", role: "alert" },
      `Lost track of the build (${err.message}). It may still finish: see Build jobs, or reload the page in a moment.`));
  }

  /** The deploy was refused because test scenarios are red: say which, offer to update the tests
   * when they only expect words the draft changed, or to deploy anyway. */
  redScenarios(body) {
    const red = ((body.report && body.report.results) || []).filter((r) => r.status !== "passed");
    const updateHost = h("div", { class: "tests-update-host" });
    fill(this.deployResultEl, h("div", { class: "message error", role: "alert", "data-testid": "red-scenarios" },
      h("p", {}, `Not deployed: ${red.length} test scenario${red.length === 1 ? " fails" : "s fail"} with these rules. Nothing was changed.`),
      h("ul", {}, red.map((r) => h("li", {}, h("b", {}, r.name)))),
      updateHost,
      h("details", { class: "red-details" }, h("summary", {}, "What each test expected (details)"),
        h("ul", {}, red.map((r) => h("li", {}, h("b", {}, r.name), ": ", (r.failures[0] && r.failures[0].message) || r.status)))),
      h("p", {}, "Fix the rules (or the scenario, if the change is wanted), or deploy anyway."),
      h("div", { class: "buttons" },
        h("button", { class: "secondary", "data-testid": "show-tests", onclick: () => this.testsView.run({ reveal: true }) }, "Show the tests"),
        h("button", { class: "danger", "data-testid": "deploy-anyway", onclick: () => this.deploy(true) }, "Deploy anyway"))));
    offerTestUpdate(updateHost, { name: this.name, files: this.files(), apply: (files, { allFixed }) => this.updateTests(files, allFixed) });
  }

  /** Put the rewritten test files into their editors; deploy again when nothing else was red. */
  updateTests(files, allFixed) {
    for (const [file, text] of Object.entries(files)) {
      if (this.views[file]) setText(this.views[file], text);
    }
    if (allFixed) this.deploy();
    else this.testsView.run({ reveal: true });
  }

  conflict(current) {
    const started = this.base;
    const compare = `#/history/${encodeURIComponent(this.name)}?from=${started}&to=${current}`;
    fill(this.deployResultEl, h("div", { class: "message warning", role: "alert", "data-testid": "conflict" },
      h("p", {}, `Not deployed: someone else deployed version ${current} while you were editing (you started from version ${started}). `,
        "Your changes are still here; nothing was lost."),
      h("div", { class: "buttons" },
        h("a", { class: "button secondary", href: compare, target: "_blank", rel: "noopener" }, `See what changed in version ${current}`),
        h("button", { class: "secondary", onclick: () => {
          this.base = current;
          this.storeDraft();
          this.deploy();
        } }, `Deploy mine anyway (replaces version ${current}; it stays in the history)`))));
  }
}

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

/** Server errors ({file, line, column, message}) as problems. */
function normalizeErrors(errors) {
  if (!Array.isArray(errors)) return [];
  return errors.filter((e) => e && (e.message || e.msg)).map((e) => ({
    file: e.file || "", line: Number(e.line) || 0, column: Number(e.column) || 0,
    severity: e.severity === "warning" ? "warning" : "error", message: String(e.message || e.msg), source: "compiler",
    sheet: e.sheet || "", cell: e.cell || "",
  }));
}

function describeFactError(e) {
  const where = [`Fact ${e.index !== undefined ? Number(e.index) + 1 : "?"}`];
  if (e.type) where.push(`(${e.type})`);
  if (e.field) where.push(`field “${e.field}”`);
  return `${where.join(" ")}: ${e.message}`;
}

/** "line L, column C: message" for a JSON.parse error (browsers say "position N"). */
function jsonErrorWhere(text, err) {
  const position = /position (\d+)/.exec(err.message);
  if (!position) return err.message;
  const before = text.slice(0, Number(position[1]));
  const line = before.split("\n").length;
  const column = before.length - before.lastIndexOf("\n");
  return `line ${line}, column ${column}: ${err.message.replace(/\s*\(line \d+ column \d+\)/, "")}`;
}

function sampleValue(field, javaType) {
  const t = String(javaType).toLowerCase();
  if (field === "id") return "new-1";
  if (/int|long|short|byte/.test(t)) return 0;
  if (/double|float|number|bigdecimal/.test(t)) return 0.0;
  if (/bool/.test(t)) return false;
  return "";
}
