// The Workflows section: the visual workflow editor (the papers' service -> process -> module
// hierarchy). The owner inserts, reorders and removes steps (drag and drop or keyboard), fills a
// form per step typed from the palette (robots, rule sets, ontology values to pick from), watches
// the checks as they type, saves live with versions, compares and rolls back, and runs the
// workflow on the simulated robots, watching the trace step by step. YAML stays the storage
// format: the YAML tab shows what is saved and stays editable; the generated Python is shown too.
// The canvas (process view), palette, forms, versions and run panel are methods of the editor written
// in their own modules (workflow-canvas.js, workflow-palette.js, workflow-forms.js, workflow-versions.js,
// workflow-run.js); the document operations are in workflow-model.js.

import "./workflow-view.css";
import { api, getToken } from "./api.js";
import { h, fill, debounce } from "./dom.js";
import { createEditor, setText, showProblems } from "./editor.js";
import { fieldLabel } from "./field-label.js";
import { getIn, allSteps, findStep, locateProblem, samePath } from "./workflow-model.js";
import { canvasMethods } from "./workflow-canvas.js";
import { paletteMethods } from "./workflow-palette.js";
import { formMethods } from "./workflow-forms.js";
import { versionMethods, wfPath } from "./workflow-versions.js";
import { runMethods } from "./workflow-run.js";

const CHECK_DELAY_MS = 300;
const TABS = [
  ["process", "Process view"], ["scenario", "Scenario view"], ["yaml", "YAML"], ["python", "Python"],
  ["versions", "Versions"],
];

/** Open workflow `name` (or the first one) in `main`. */
export async function showWorkflows(main, ctx, name, params) {
  let list;
  try {
    list = await api("GET", "/api/workflows");
  } catch (err) {
    ctx.hideSidebar();
    fill(main, h("div", { class: "message error", role: "alert" }, `Cannot list the workflows: ${err.message}`));
    return {};
  }
  ctx.setSidebar("Workflows", list.map((w) => h("li", { class: w.name === name ? "active" : "" },
    h("a", { href: ctx.href("workflows", w.name), "data-workflow": w.name },
      h("span", { class: "name" }, w.title || w.name),
      h("span", { class: "meta" }, `${w.name} · version ${w.version}`)))));
  if (!name) {
    if (list.length) ctx.replace(ctx.href("workflows", list[0].name));
    else fill(main, h("p", { class: "muted" }, "There are no workflows yet. Put YAML files under workflows/ and restart the gateway."));
    return {};
  }
  fill(main, h("p", { class: "muted" }, `Opening “${name}”…`));
  let current;
  let palette;
  try {
    [current, palette] = await Promise.all([api("GET", wfPath(name)), api("GET", "/api/workflows/palette")]);
  } catch (err) {
    fill(main, h("div", { class: "message error", role: "alert" }, `Cannot open the workflow “${name}”: ${err.message}`));
    return {};
  }
  const view = new WorkflowEditor(main, ctx, current, palette, params);
  return { dispose: () => view.dispose() };
}

class WorkflowEditor {
  constructor(main, ctx, current, palette, params) {
    this.main = main;
    this.ctx = ctx;
    this.palette = palette;
    this.name = current.name;
    this.version = current.version; // the live version
    this.base = current.version; // the version the edits started from (sent with the save)
    this.title = current.title || current.name;
    this.savedText = current.text;
    this.text = current.text;
    this.doc = null;
    this.problems = [];
    this.clientProblems = [];
    this.scenario = current.scenario_view;
    this.selected = null; // path of the selected step
    this.slot = null; // {list, index}: an explicit insertion point (end of a list, an empty arm)
    this.editingModule = null;
    this.tab = params && TABS.some(([id]) => id === params.get("tab")) ? params.get("tab") : "process";
    this.seq = 0;
    this.undoStack = [];
    this.redoStack = [];
    this.onKey = (event) => this.historyKeys(event);
    document.addEventListener("keydown", this.onKey);
    this.timers = [];
    this.checkSoon = debounce(() => this.check(), CHECK_DELAY_MS);
    const draft = readDraft(this.name);
    if (draft && draft.text !== current.text) {
      this.text = draft.text;
      this.base = draft.base;
    }
    this.build();
    if (this.dirty) {
      fill(this.saveMsgEl, h("div", { class: "message info", role: "status" },
        `Your unsaved edits (started from version ${this.base}) are back. “Discard changes” drops them.`));
    }
    this.check({ text: this.text }).then(() => this.renderAll());
  }

  dispose() {
    document.removeEventListener("keydown", this.onKey);
    clearInterval(this.revealTimer);
    this.checkSoon.cancel();
    this.timers.forEach(clearTimeout);
    this.disposed = true;
  }

  get dirty() {
    return this.text !== this.savedText;
  }

  // ------------------------------------------------------------------ layout

  build() {
    this.statusEl = h("span", { class: "check-status pending", "data-testid": "wf-status", role: "status" }, "Checking…");
    this.versionEl = h("span", { class: "badge live", "data-testid": "wf-version" });
    this.dirtyEl = h("span", { class: "badge dirty", hidden: true }, "unsaved changes");
    this.tabEls = TABS.map(([id, label]) => h("button", {
      class: "tab", role: "tab", id: `wf-tab-${id}`, "aria-controls": "wf-panel", "data-tab": id,
      onclick: () => this.showTab(id), onkeydown: (e) => this.tabKeys(e, id),
    }, h("span", { class: "tab-name" }, label)));
    this.panelEl = h("div", { id: "wf-panel", role: "tabpanel", class: "wf-panel" });
    this.sideEl = h("aside", { class: "wf-side", "aria-label": "Palette and step form" });
    this.problemsEl = h("ul", { class: "problems", "data-testid": "wf-problems", "aria-label": "Problems" });
    this.commentEl = h("input", { type: "text", id: "wf-comment", "aria-label": "What did you change? (comment for the version)",
      placeholder: "What did you change?" });
    this.saveBtn = h("button", { class: "big primary", "data-testid": "wf-save", onclick: () => this.save() }, "Save and make live");
    this.discardBtn = h("button", { class: "secondary", onclick: () => this.discard() }, "Discard changes");
    this.saveMsgEl = h("div", { "aria-live": "polite", "data-testid": "wf-save-message" });
    this.runEl = h("section", { class: "card wf-run", "aria-label": "Run" });
    this.undoBtn = h("button", { class: "secondary", "aria-label": "Undo the last change", title: "Undo (Ctrl+Z)", onclick: () => this.undo() }, "↶ Undo");
    this.redoBtn = h("button", { class: "secondary", "aria-label": "Redo", title: "Redo (Ctrl+Y)", onclick: () => this.redo() }, "↷ Redo");
    const author = this.ctx.isAuthor();
    fill(this.main, h("section", { class: "wf-editor" },
      h("div", { class: "title-row" }, h("h1", {}, this.title), h("span", { class: "muted" }, this.name),
        this.versionEl, this.dirtyEl, this.statusEl),
      h("div", { class: "card wf-savebar" },
        h("label", { class: "field wf-comment", for: "wf-comment" }, "Comment", this.commentEl),
        h("div", { class: "buttons" }, author ? this.saveBtn : h("span", { class: "hint" }, "Only authors may save."), this.discardBtn),
        this.saveMsgEl),
      this.problemsEl,
      h("div", { class: "wf-tabrow" },
        h("div", { class: "tabs", role: "tablist", "aria-label": "Views of the workflow" }, this.tabEls),
        h("div", { class: "wf-history" }, this.undoBtn, this.redoBtn)),
      h("div", { class: "wf-columns" }, this.panelEl, this.sideEl),
      this.runEl));
    this.renderRun();
  }

  tabKeys(event, id) {
    const index = TABS.findIndex(([t]) => t === id);
    const next = event.key === "ArrowRight" ? index + 1 : event.key === "ArrowLeft" ? index - 1 : null;
    if (next === null) return;
    event.preventDefault();
    const [target] = TABS[(next + TABS.length) % TABS.length];
    this.showTab(target);
    this.tabEls.find((t) => t.dataset.tab === target).focus();
  }

  async showTab(id) {
    if (this.tab === "yaml" && id !== "yaml" && this.yamlView) {
      // the views must show what the YAML says now, not before its last keys
      if (this.yamlCheck) this.yamlCheck.cancel();
      this.tab = id;
      await this.check({ text: this.yamlView.state.doc.toString() });
      this.yamlView = null;
    }
    this.tab = id;
    this.renderAll();
  }

  renderAll() {
    if (this.disposed) return;
    this.versionEl.textContent = `version ${this.version} live`;
    this.historyButtons();
    this.undoBtn.hidden = this.redoBtn.hidden = this.tab !== "process" && this.tab !== "scenario";
    this.dirtyEl.hidden = !this.dirty;
    for (const t of this.tabEls) t.setAttribute("aria-selected", String(t.dataset.tab === this.tab));
    this.panelEl.setAttribute("aria-labelledby", `wf-tab-${this.tab}`);
    const visual = this.tab === "process" || this.tab === "scenario";
    this.sideEl.hidden = !visual;
    this.panelEl.classList.toggle("wide", !visual);
    if (this.tab === "process") this.renderProcessView();
    else if (this.tab === "scenario") this.renderScenario();
    else if (this.tab === "yaml") this.renderYaml();
    else if (this.tab === "python") this.renderPython();
    else this.renderVersions();
    if (visual) this.renderSide();
    this.renderProblems();
  }

  // ------------------------------------------------------------------ checking as you type

  /** Validate the document (after a visual edit) or a text (YAML tab); the newest answer wins. */
  async check(body) {
    const seq = ++this.seq;
    const payload = body || { document: this.doc, previous_text: this.savedText };
    fill(this.statusEl, "Checking…");
    this.statusEl.className = "check-status pending";
    let result;
    try {
      result = await api("POST", "/api/workflows/validate", payload);
    } catch (err) {
      if (seq !== this.seq) return;
      this.problems = [{ path: "", line: 0, column: 0, message: `The check failed: ${err.message}` }];
      this.renderStatus();
      return;
    }
    if (seq !== this.seq || this.disposed) return;
    this.text = result.text;
    if (payload.text !== undefined || !this.doc) {
      this.doc = result.document || null;
      this.lastDoc = JSON.stringify(this.doc); // edits of the YAML have the YAML editor's own undo
      this.lastCoalesce = null;
    }
    this.keepDraft();
    this.problems = result.problems || [];
    if (result.valid) this.scenario = result.scenario_view;
    this.parsed = !!result.document;
    this.renderStatus();
    if (payload.text !== undefined && this.tab !== "yaml") this.renderAll();
    if (this.tab === "yaml" && this.yamlView) {
      if (payload.text === undefined && this.yamlView.state.doc.toString() !== this.text) setText(this.yamlView, this.text);
      showProblems(this.yamlView, this.problems);
    }
  }

  /** Unsaved edits survive a reload or a visit to another workflow (dropped on save or discard). */
  keepDraft() {
    try {
      if (this.dirty) localStorage.setItem(draftKey(this.name), JSON.stringify({ text: this.text, base: this.base }));
      else localStorage.removeItem(draftKey(this.name));
    } catch {
      // storage full or disabled: the edits just do not survive a reload
    }
  }

  /** Keep the document as it was before this edit for Undo; typing into one field is one edit. */
  remember() {
    const now = JSON.stringify(this.doc);
    const coalesce = this.coalesce || null;
    this.coalesce = null;
    if (this.lastDoc !== undefined && now !== this.lastDoc) {
      if (!coalesce || coalesce !== this.lastCoalesce) this.undoStack.push(this.lastDoc);
      this.redoStack = [];
    }
    this.lastCoalesce = coalesce;
    this.lastDoc = now;
    this.historyButtons();
  }

  historyButtons() {
    this.undoBtn.disabled = !this.undoStack.length;
    this.redoBtn.disabled = !this.redoStack.length;
  }

  undo() {
    this.travel(this.undoStack, this.redoStack, "Undone");
  }

  redo() {
    this.travel(this.redoStack, this.undoStack, "Redone");
  }

  travel(from, to, word) {
    if (!from.length || !this.doc) return this.say(`Nothing to ${word === "Undone" ? "undo" : "redo"}.`);
    to.push(JSON.stringify(this.doc));
    this.doc = JSON.parse(from.pop());
    this.lastDoc = JSON.stringify(this.doc);
    this.lastCoalesce = null;
    this.renaming = null;
    if (this.selected && !getIn(this.doc, this.selected)) this.selected = null;
    if (this.editingModule && !(this.doc.modules || {})[this.editingModule]) this.editingModule = null;
    this.seq += 1;
    const focusInSteps = this.panelEl.contains(document.activeElement);
    if (this.tab !== "process" && this.tab !== "scenario") this.tab = "process";
    this.renderAll();
    if (focusInSteps && this.selected) this.focusStep(this.selected);
    this.historyButtons();
    this.say(`${word}.`);
    this.checkSoon();
  }

  /** Ctrl+Z / Ctrl+Y (Ctrl+Shift+Z) in the visual views; text fields and the YAML editor keep theirs. */
  historyKeys(event) {
    if (!(event.ctrlKey || event.metaKey) || event.altKey || !this.main.contains(event.target)) return;
    if (this.tab !== "process" && this.tab !== "scenario") return;
    if (event.target.closest("input, textarea, select, .cm-editor")) return;
    const key = event.key.toLowerCase();
    if (key === "z" && !event.shiftKey) {
      event.preventDefault();
      this.undo();
    } else if (key === "y" || (key === "z" && event.shiftKey)) {
      event.preventDefault();
      this.redo();
    }
  }

  /** After every visual edit: re-draw, then check (debounced). */
  changed({ keepForm = false } = {}) {
    this.remember();
    this.seq += 1; // an answer to an older check must not overwrite this edit
    this.dirtyEl.hidden = false;
    this.clientProblems = this.requiredProblems();
    fill(this.statusEl, "Checking…");
    this.statusEl.className = "check-status pending";
    if (this.tab === "process") this.renderProcessView();
    if (!keepForm) this.renderSide();
    else this.markFieldErrors();
    this.renderProblems();
    this.checkSoon();
  }

  /** Required parameters left empty (the palette says which are required). */
  requiredProblems() {
    if (!this.doc) return [];
    const out = [];
    for (const { step, path } of allSteps(this.doc)) {
      if (!step || !step.module) continue;
      for (const param of this.paramsOfModule(step.module)) {
        if (!param.required || param.name === "robot") continue;
        const module = (this.doc.modules || {})[step.module] || {};
        const value = (step.with || {})[param.name] ?? (module.params || {})[param.name];
        if (value === undefined || value === "") {
          out.push({ path: "", stepPath: path, field: `with.${param.name}`, client: true, line: 0, column: 0,
            message: `${param.name} is required` });
        }
      }
    }
    return out;
  }

  allProblems() {
    return [...this.clientProblems, ...this.problems];
  }

  renderStatus() {
    this.clientProblems = this.requiredProblems();
    const count = this.allProblems().length;
    this.statusEl.className = `check-status ${count ? "error" : "ok"}`;
    fill(this.statusEl, count ? `✗ ${count} problem${count > 1 ? "s" : ""}` : "✓ No problems");
    this.dirtyEl.hidden = !this.dirty;
    this.renderProblems();
    this.markFieldErrors();
    if (this.tab === "process") this.markStepErrors();
  }

  /** "Step “pause_2”, field “seconds”: 'abc' is not a number of seconds" (the field as its form labels it) */
  describeProblem(problem) {
    const where = problem.client ? { stepPath: problem.stepPath, stepId: getIn(this.doc, problem.stepPath)?.id, field: problem.field }
      : this.doc ? locateProblem(this.doc, problem) : { field: problem.path };
    let text = "";
    const field = fieldLabel(where.field);
    if (where.stepId || where.stepPath) text = `Step “${where.stepId || "?"}”${field ? `, field “${field}”` : ""}: `;
    else if (where.module) text = `Module “${where.module}”${field ? `, field “${field}”` : ""}: `;
    else if (problem.path) text = `${problem.path}: `;
    const line = problem.line ? ` (YAML line ${problem.line})` : "";
    return { where, text: `${text}${problem.message}${line}` };
  }

  renderProblems() {
    const problems = this.allProblems();
    this.problemsEl.hidden = problems.length === 0;
    fill(this.problemsEl, problems.map((p) => {
      const { where, text } = this.describeProblem(p);
      return h("li", { class: "error" }, h("button", {
        class: "problem", onclick: () => {
          if (where.stepPath && getIn(this.doc, where.stepPath)) this.select(where.stepPath, { focusField: where.field });
          else if (where.module) this.editModule(where.module);
          else this.showTab("yaml");
        },
      }, h("span", {}, text)));
    }));
  }

  problemsFor(stepPath) {
    return this.allProblems().map((p) => ({ p, where: p.client ? { stepPath: p.stepPath, field: p.field } : locateProblem(this.doc, p) }))
      .filter(({ where }) => samePath(where.stepPath, stepPath));
  }

  // ------------------------------------------------------------------ scenario view

  renderScenario() {
    const sc = this.scenario;
    if (!sc) {
      fill(this.panelEl, h("p", { class: "muted" }, "The scenario appears when the workflow has no problems."));
      return;
    }
    const stale = this.allProblems().length > 0;
    fill(this.panelEl, h("div", { class: "wf-scenario", "data-testid": "wf-scenario" },
      stale ? h("p", { class: "message warning" }, "Showing the last version without problems.") : null,
      h("table", {}, h("caption", { class: "sr-only" }, "Scenario: steps in run order, one column per actor"),
        h("thead", {}, h("tr", {}, h("th", { scope: "col" }, "#"), sc.lanes.map((l) => h("th", { scope: "col" }, sc.labels[l] || l)))),
        h("tbody", {}, sc.steps.map((row, i) => h("tr", { "data-step": row.id },
          h("td", {}, String(i + 1)),
          sc.lanes.map((lane) => h("td", {}, lane === row.actor ? h("button", {
            class: `wf-scenario-step k-${row.kind}`, style: `margin-left:${row.depth * 1}rem`,
            onclick: () => { const found = findStep(this.doc, row.id); if (found) this.select(found.path); },
          }, row.branch ? h("span", { class: "muted" }, `${row.branch} · `) : null, row.label) : null))))))));
  }

  // ------------------------------------------------------------------ YAML and Python

  renderYaml() {
    const host = h("div", { class: "editor-host wf-yaml" });
    fill(this.panelEl, h("p", { class: "hint" }, "The workflow as it is stored. Edits here are checked as you type and shown in the other views."), host);
    this.yamlView = createEditor(host, {
      doc: this.text, fileName: `${this.name}.yaml`, label: "Workflow YAML",
      onChange: (text) => {
        this.text = text;
        this.dirtyEl.hidden = !this.dirty;
        this.seq += 1;
        this.yamlCheck = this.yamlCheck || debounce((t) => this.check({ text: t }), CHECK_DELAY_MS);
        this.yamlCheck(text);
      },
    });
    showProblems(this.yamlView, this.problems);
  }

  async renderPython() {
    fill(this.panelEl, h("p", { class: "muted" }, "Generating…"));
    try {
      const response = await fetch(wfPath(this.name, "/code"), { headers: authHeaders() });
      if (!response.ok) throw new Error(`error ${response.status}`);
      const code = await response.text();
      const host = h("div", { class: "editor-host wf-python", "data-testid": "wf-python" });
      fill(this.panelEl, h("p", { class: "hint" }, `The ROS 2 node generated from the saved version ${this.version} (read-only).`), host);
      createEditor(host, { doc: code, fileName: `${this.name}_node.py`, readOnly: true, label: "Generated Python (read-only)" });
    } catch (err) {
      fill(this.panelEl, h("div", { class: "message error", role: "alert" }, `Cannot generate the code: ${err.message}`));
    }
  }
}

// The canvas, palette, forms, versions and run panel are the editor's methods too, each in its module.
Object.assign(WorkflowEditor.prototype, canvasMethods, paletteMethods, formMethods, versionMethods, runMethods);

function draftKey(name) {
  return `printeps.workbench.workflow-draft.${name}`;
}

function readDraft(name) {
  try {
    const draft = JSON.parse(localStorage.getItem(draftKey(name)) || "null");
    return draft && typeof draft.text === "string" && Number.isInteger(draft.base) ? draft : null;
  } catch {
    return null;
  }
}

function authHeaders() {
  const token = getToken();
  return token ? { Authorization: `Bearer ${token}` } : {};
}
