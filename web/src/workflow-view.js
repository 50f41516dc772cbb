// The Workflows section: the visual workflow editor (the papers' service -> process -> module
// hierarchy). The owner inserts, reorders and removes steps (drag and drop or keyboard), fills a
// form per step typed from the palette (robots, rule sets, ontology values to pick from), watches
// the checks as they type, saves live with versions, compares and rolls back, and runs the
// workflow on the simulated robots, watching the trace step by step. YAML stays the storage
// format: the YAML tab shows what is saved and stays editable; the generated Python is shown too.

import "./workflow-view.css";
import { fieldLabel } from "./field-label.js";
import { paletteRows } from "./palette-entries.js";
import { h, fill, when, debounce } from "./dom.js";
import { api, getToken } from "./api.js";
import { createEditor, setText, showProblems } from "./editor.js";
import { MergeView } from "@codemirror/merge";
import { basicSetup } from "codemirror";
import { EditorState } from "@codemirror/state";
import { EditorView } from "@codemirror/view";
import { languageFor } from "./lang.js";
import {
  getIn, allSteps, findStep, uniqueStepId, insertStep, removeStep, shiftStep, moveStep, listName,
  moduleFor, addModule, stepSummary, locateProblem, samePath, renameModule, renameProcess, removeProcess,
  variableValue, variableText, renameVariable, newVariableName, nameProblem,
} from "./workflow-model.js";

const CHECK_DELAY_MS = 300;
const TRACE_STEP_MS = 300; // one trace entry at a time, so the eye can follow the run
const RUN_POLL_MS = 250;
const TABS = [
  ["process", "Process view"], ["scenario", "Scenario view"], ["yaml", "YAML"], ["python", "Python"],
  ["versions", "Versions"],
];

/** Module kinds in the owner's words (the badges of the steps and the palette). */
const KIND_WORDS = {
  ros_service: "robot", ros_topic: "message", fire_rules: "rules", ontology_value: "knowledge", wait: "wait",
  manual: "staff", branch: "branch", process: "process", set: "set", module: "module",
};
const kindWord = (kind) => KIND_WORDS[kind] || String(kind).replace("_", " ");

const wfPath = (name, rest = "") => `/api/workflows/${encodeURIComponent(name)}${rest}`;
const pathKey = (path) => path.join("/");

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
    if (list.length) location.replace(ctx.href("workflows", list[0].name));
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

  // ------------------------------------------------------------------ process view

  renderProcessView() {
    if (!this.doc) {
      fill(this.panelEl, h("div", { class: "message error", role: "alert" },
        "The YAML cannot be read, so the steps cannot be drawn. Fix it in the YAML tab (the problems above say where)."));
      return;
    }
    const doc = this.doc;
    const route = doc.route || {};
    const services = (route.services || []).filter((s) => (doc.services || {})[s]);
    const inRoute = new Set(services.flatMap((s) => doc.services[s].processes || []));
    const others = Object.keys(doc.processes || {}).filter((p) => !inRoute.has(p));
    fill(this.panelEl, h("div", { class: "wf-process-view", "data-testid": "wf-process-view" },
      h("p", { class: "hint wf-keys" }, "Keys on a step: Enter edits it, Alt+↑ / Alt+↓ move it, Delete removes it; Ctrl+Z undoes."),
      h("p", { class: "wf-route" }, h("span", { class: "badge" }, "start"), ` ${route.start || "start"}`),
      services.map((s) => h("section", { class: "wf-service", "aria-label": `Service ${s}` },
        h("h2", {}, h("span", { class: "wf-tag" }, "Service"), ` ${s}`),
        doc.services[s].description ? h("p", { class: "hint" }, doc.services[s].description) : null,
        (doc.services[s].processes || []).filter((p) => (doc.processes || {})[p]).map((p) => this.processBox(p)),
        this.newProcessForm(s))),
      others.length ? h("section", { class: "wf-service" }, h("h2", {}, "Other processes"), others.map((p) => this.processBox(p))) : null,
      h("p", { class: "wf-route" }, h("span", { class: "badge" }, "end"), ` ${route.end || "end"}`)));
    this.markStepErrors();
    this.markTrace();
  }

  /** "+ Add a process" to a service: a name, then its first step from the palette. */
  newProcessForm(service) {
    const id = `wf-new-process-${service}`;
    const nameEl = h("input", { type: "text", id, placeholder: "e.g. invite_to_sit", "aria-label": `Name of a new process of service ${service}` });
    const errorEl = h("span", { class: "wf-field-error", role: "alert" });
    const add = (event) => {
      event.preventDefault();
      const name = nameEl.value.trim();
      const problem = nameProblem("process", name, !!(this.doc.processes || {})[name]);
      if (problem) {
        errorEl.textContent = problem;
        return nameEl.focus();
      }
      this.doc.processes[name] = { steps: [] };
      this.doc.services[service].processes = [...(this.doc.services[service].processes || []), name];
      this.slot = { list: ["processes", name, "steps"], index: 0 };
      this.selected = null;
      this.say(`Process ${name} added to service ${service}; add its steps from the palette.`);
      this.changed();
      this.panelEl.querySelector(`[data-slot="${CSS.escape(pathKey(this.slot.list))}"]`)?.focus();
    };
    return h("form", { class: "wf-new-process", onsubmit: add },
      h("label", { for: id }, "Add a process: "), nameEl, h("button", { class: "secondary", type: "submit" }, "Add process"), errorEl);
  }

  processBox(name) {
    const process = this.doc.processes[name];
    const heading = this.renaming === name ? this.renameForm(name)
      : h("h3", {}, h("span", { class: "wf-tag" }, "Process"), ` ${name}`,
        h("span", { class: "wf-process-tools" },
          h("button", { class: "secondary small", "aria-label": `Rename process ${name}`, onclick: () => this.startRename(name) }, "Rename"),
          h("button", { class: "secondary small", "aria-label": `Remove process ${name}`, onclick: () => this.removeProcessOf(name) }, "Remove")));
    return h("div", { class: "wf-process", "data-process": name },
      heading,
      process.description ? h("p", { class: "hint" }, process.description) : null,
      this.stepList(["processes", name, "steps"], process.steps || []));
  }

  startRename(name) {
    this.renaming = name;
    this.renderProcessView();
    this.panelEl.querySelector(".wf-rename input")?.select();
  }

  /** The heading of a process being renamed: its name in a field; Enter renames, Escape cancels. */
  renameForm(name) {
    const nameEl = h("input", { type: "text", value: name, "aria-label": `New name of process ${name}` });
    const errorEl = h("span", { class: "wf-field-error", role: "alert" });
    const cancel = () => {
      this.renaming = null;
      this.renderProcessView();
      this.panelEl.querySelector(`[aria-label="Rename process ${CSS.escape(name)}"]`)?.focus();
    };
    const rename = (event) => {
      event.preventDefault();
      const to = nameEl.value.trim();
      const problem = renameProcess(this.doc, name, to);
      if (problem) {
        errorEl.textContent = problem;
        return nameEl.focus();
      }
      this.renamed(name, to);
    };
    nameEl.addEventListener("keydown", (event) => { if (event.key === "Escape") cancel(); });
    return h("form", { class: "wf-rename", onsubmit: rename },
      h("span", { class: "wf-tag" }, "Process"), " ", nameEl,
      h("button", { class: "secondary small", type: "submit" }, "Rename"),
      h("button", { class: "secondary small", type: "button", onclick: cancel }, "Cancel"), errorEl);
  }

  /** After :func:`renameProcess`: selection and insertion place follow, the view is redrawn. */
  renamed(from, to) {
    this.renaming = null;
    if (from === to) return this.renderProcessView();
    const moved = (path) => (path && path[0] === "processes" && path[1] === from ? ["processes", to, ...path.slice(2)] : path);
    this.selected = moved(this.selected);
    if (this.slot) this.slot = { ...this.slot, list: moved(this.slot.list) };
    this.say(`Process ${from} renamed to ${to}.`);
    this.changed();
    this.panelEl.querySelector(`[aria-label="Rename process ${CSS.escape(to)}"]`)?.focus();
  }

  /** Removes a process with its steps, and from the services that list it (Ctrl+Z undoes). */
  removeProcessOf(name) {
    const steps = removeProcess(this.doc, name);
    const inIt = (path) => path && path[0] === "processes" && path[1] === name;
    if (inIt(this.selected)) this.selected = null;
    if (this.slot && inIt(this.slot.list)) this.slot = null;
    this.say(`Process ${name} removed with its ${steps} step${steps === 1 ? "" : "s"}; Undo (Ctrl+Z) brings it back.`);
    this.changed();
  }

  stepList(listPath, steps) {
    const label = listName(this.doc, listPath);
    const slotActive = this.slot && samePath(this.slot.list, listPath);
    return h("div", { class: "wf-list" },
      h("ol", { class: "wf-steps", "aria-label": `Steps of ${label}` }, steps.map((step, i) => this.stepItem([...listPath, i], step))),
      h("button", {
        class: `wf-slot${slotActive ? " active" : ""}`, "aria-pressed": String(!!slotActive), "data-slot": pathKey(listPath),
        "aria-label": `Add new steps at the end of the ${label}`,
        onclick: () => this.chooseSlot(listPath, steps.length),
        ondragover: (e) => this.dragOver(e), ondragleave: (e) => e.currentTarget.classList.remove("drop"),
        ondrop: (e) => this.drop(e, listPath, steps.length),
      }, steps.length ? `+ add at the end of the ${label}` : `+ add steps to the ${label} (empty)`));
  }

  stepItem(path, step) {
    const selected = samePath(this.selected, path);
    const id = step && step.id ? step.id : `(step ${path[path.length - 1] + 1})`;
    const kind = step.module ? ((this.doc.modules || {})[step.module] || {}).kind || "module"
      : step.if !== undefined ? "branch" : step.process ? "process" : "set";
    const main = h("button", {
      class: "wf-step-main", "aria-pressed": String(selected), "data-step": step.id || "",
      "aria-label": `Step ${id}: ${stepSummary(step)}. Alt+Arrow keys move it, Delete removes it.`,
      onclick: () => this.select(path), onkeydown: (e) => this.stepKeys(e, path),
    }, h("span", { class: `wf-kind k-${kind}` }, kindWord(kind)), h("span", { class: "wf-id" }, id),
    h("span", { class: "wf-summary" }, stepSummary(step)));
    const list = getIn(this.doc, path.slice(0, -1));
    const index = path[path.length - 1];
    const li = h("li", {
      class: `wf-step${selected ? " selected" : ""}`, draggable: "true", "data-path": pathKey(path), "data-step": step.id || "",
      ondragstart: (e) => { e.stopPropagation(); e.dataTransfer.setData("application/x-wf-step", JSON.stringify(path)); e.dataTransfer.effectAllowed = "move"; },
      ondragover: (e) => this.dragOver(e), ondragleave: (e) => e.currentTarget.classList.remove("drop"),
      ondrop: (e) => this.drop(e, path.slice(0, -1), index),
    },
    h("div", { class: "wf-step-row" }, main,
      h("span", { class: "wf-step-tools" },
        h("button", { class: "icon", "aria-label": `Move step ${id} up`, title: "Move up (Alt+↑)", disabled: index === 0,
          onclick: () => this.shift(path, -1) }, "↑"),
        h("button", { class: "icon", "aria-label": `Move step ${id} down`, title: "Move down (Alt+↓)", disabled: index === list.length - 1,
          onclick: () => this.shift(path, 1) }, "↓"),
        h("button", { class: "icon danger-text", "aria-label": `Remove step ${id}`, title: "Remove (Delete)",
          onclick: () => this.remove(path) }, "✕"))),
    h("div", { class: "wf-step-errors" }));
    if (step.if !== undefined) {
      li.append(h("div", { class: "wf-arms" },
        h("div", { class: "wf-arm" }, h("div", { class: "wf-arm-title" }, "then"), this.stepList([...path, "then"], step.then || [])),
        h("div", { class: "wf-arm" }, h("div", { class: "wf-arm-title" }, "else"), this.stepList([...path, "else"], step.else || []))));
    }
    return li;
  }

  markStepErrors() {
    for (const li of this.panelEl.querySelectorAll("li.wf-step")) {
      const path = li.dataset.path.split("/").map((x) => (/^\d+$/.test(x) ? Number(x) : x));
      const mine = this.problemsFor(path);
      li.classList.toggle("has-error", mine.length > 0);
      const box = li.querySelector(":scope > .wf-step-errors");
      fill(box, mine.map(({ p }) => h("div", { class: "wf-error" }, this.describeProblem(p).text)));
    }
  }

  stepKeys(event, path) {
    if (event.altKey && (event.key === "ArrowUp" || event.key === "ArrowDown")) {
      event.preventDefault();
      this.shift(path, event.key === "ArrowUp" ? -1 : 1);
    } else if (event.key === "Delete") {
      event.preventDefault();
      this.remove(path);
    }
  }

  focusStep(path) {
    const li = path && this.panelEl.querySelector(`li.wf-step[data-path="${CSS.escape(pathKey(path))}"]`);
    const target = li ? li.querySelector(":scope > .wf-step-row .wf-step-main") : null;
    if (target) target.focus();
  }

  shift(path, delta) {
    const to = shiftStep(this.doc, path, delta);
    if (samePath(to, path)) return;
    this.selected = to;
    this.slot = null;
    this.say(`Step ${getIn(this.doc, to).id} moved ${delta < 0 ? "up" : "down"}.`);
    this.changed();
    this.focusStep(to);
  }

  remove(path) {
    const list = getIn(this.doc, path.slice(0, -1));
    const index = path[path.length - 1];
    const removed = removeStep(this.doc, path);
    const stillThere = getIn(this.doc, path.slice(0, -1));
    let next = null;
    if (stillThere && stillThere.length) next = [...path.slice(0, -1), Math.min(index, stillThere.length - 1)];
    this.selected = next;
    this.slot = null;
    this.say(`Step ${removed && removed.id} removed.`);
    this.changed();
    if (next) this.focusStep(next);
    else {
      const slot = this.panelEl.querySelector(`[data-slot="${CSS.escape(pathKey(path.slice(0, -1)))}"]`);
      (slot || this.panelEl.querySelector(".wf-step-main") || this.panelEl).focus();
    }
    return list;
  }

  dragOver(event) {
    const types = [...event.dataTransfer.types];
    if (!types.includes("application/x-wf-step") && !types.includes("application/x-wf-palette")) return;
    event.preventDefault();
    event.stopPropagation();
    event.currentTarget.classList.add("drop");
  }

  drop(event, listPath, index) {
    event.preventDefault();
    event.stopPropagation();
    event.currentTarget.classList.remove("drop");
    const stepData = event.dataTransfer.getData("application/x-wf-step");
    const paletteData = event.dataTransfer.getData("application/x-wf-palette");
    if (stepData) {
      const to = moveStep(this.doc, JSON.parse(stepData), listPath, index);
      if (!to) return this.say("A branch cannot go into its own arm.");
      this.selected = to;
      this.say(`Step ${getIn(this.doc, to).id} moved.`);
      this.changed();
      this.focusStep(to);
    } else if (paletteData) {
      this.insertFrom(JSON.parse(paletteData), { list: listPath, index });
    }
  }

  chooseSlot(listPath, index) {
    this.slot = { list: listPath, index };
    this.selected = null;
    this.renderProcessView();
    this.renderSide();
    const slot = this.panelEl.querySelector(`[data-slot="${CSS.escape(pathKey(listPath))}"]`);
    if (slot) slot.focus();
  }

  select(path, { focusField = "" } = {}) {
    this.selected = path;
    this.slot = null;
    this.editingModule = null;
    if (this.tab !== "process" && this.tab !== "scenario") this.tab = "process";
    this.renderAll();
    if (this.tab === "process") this.focusStep(path);
    if (focusField) {
      const field = this.sideEl.querySelector(`[data-field="${CSS.escape(focusField)}"]`);
      if (field) field.focus();
    }
  }

  /** Where a new step goes: the chosen slot, else before/after the selected step, else the end of the first process. */
  insertionPoint() {
    if (this.slot) return this.slot;
    if (this.selected && getIn(this.doc, this.selected)) {
      const index = this.selected[this.selected.length - 1];
      return { list: this.selected.slice(0, -1), index: this.where === "before" ? index : index + 1 };
    }
    const first = (this.doc.route?.services || []).flatMap((s) => this.doc.services?.[s]?.processes || [])[0]
      || Object.keys(this.doc.processes || {})[0];
    return { list: ["processes", first, "steps"], index: (this.doc.processes[first].steps || []).length };
  }

  insertionText() {
    if (this.slot) return `at the end of the ${listName(this.doc, this.slot.list)}`;
    if (this.selected && getIn(this.doc, this.selected)) return `${this.where === "before" ? "before" : "after"} step “${getIn(this.doc, this.selected).id}”`;
    return "at the end of the first process";
  }

  say(text) {
    if (this.liveEl) this.liveEl.textContent = text;
  }

  // ------------------------------------------------------------------ palette and forms (side column)

  entryOf(moduleName) {
    const module = (this.doc.modules || {})[moduleName];
    if (!module) return null;
    const entries = this.palette.entries || [];
    if (module.kind === "ros_service") {
      return entries.find((e) => e.kind === "ros_service" && e.module.service === module.service)
        || entries.find((e) => e.kind === "ros_service" && e.module.type === module.type) || null;
    }
    return entries.find((e) => e.kind === module.kind) || null;
  }

  /** The typed parameters of a module's steps: from the palette, else (a module the palette does not
   *  describe, e.g. a topic) text fields for the parameters the module and the step already use. */
  paramsOfModule(moduleName, step = null) {
    const entry = this.entryOf(moduleName);
    if (entry) return entry.params || [];
    const module = (this.doc.modules || {})[moduleName] || {};
    const names = new Set([...Object.keys(module.params || {}), ...Object.keys((step && step.with) || {})]);
    names.delete("robot");
    return [...names].map((name) => ({ name, type: "string", description: "" }));
  }

  renderSide() {
    if (!this.doc || (this.tab !== "process" && this.tab !== "scenario")) {
      fill(this.sideEl);
      return;
    }
    this.liveEl = h("div", { class: "sr-only", "aria-live": "polite" });
    this.where = this.where || "after";
    const whereEl = h("select", { id: "wf-where", "aria-label": "Where new steps go", onchange: (e) => { this.where = e.target.value; this.slot = null; this.renderSide(); } },
      h("option", { value: "after", selected: this.where === "after" }, "after the selected step"),
      h("option", { value: "before", selected: this.where === "before" }, "before the selected step"));
    const form = this.editingModule ? this.moduleForm(this.editingModule)
      : this.selected && getIn(this.doc, this.selected) ? this.stepForm(this.selected) : h("p", { class: "hint" },
        "Select a step to edit it (click it, or Tab to it and press Enter).");
    fill(this.sideEl, this.liveEl,
      h("section", { class: "card wf-form", "data-testid": "wf-form", "aria-label": "Edit" }, form),
      h("section", { class: "card wf-palette", "data-testid": "wf-palette", "aria-label": "Palette" },
        h("h2", {}, "Palette"),
        h("p", { class: "hint" }, "Click a module to insert a step, or drag it onto the steps."),
        h("div", { class: "wf-where" }, h("label", { for: "wf-where" }, "New steps go "), whereEl),
        h("p", { class: "hint", "data-testid": "wf-insertion" }, `Inserting ${this.insertionText()}.`),
        this.paletteGroups()));
    this.markFieldErrors();
  }

  paletteGroups() {
    const { mine, groups } = paletteRows(this.doc, this.palette.entries, moduleFor);
    return [
      h("h3", {}, "Modules of this workflow"),
      h("ul", { class: "wf-entries", "aria-label": "Modules of this workflow" }, mine.map(({ name, module, entry, label }) => h("li", {},
        h("button", {
          class: "wf-entry", draggable: "true", "data-module": name, title: `module ${name}`,
          "aria-label": entry ? `Insert: ${entry.label}` : `Insert a ${name} step (${kindWord(module.kind)})`,
          ondragstart: (e) => e.dataTransfer.setData("application/x-wf-palette", JSON.stringify({ module: name })),
          onclick: () => this.insertFrom({ module: name }),
        }, h("span", { class: `wf-kind k-${module.kind}` }, kindWord(module.kind)), ` ${label}`),
        h("button", { class: "link wf-edit-module", "aria-label": `Edit module ${name}`, onclick: () => this.editModule(name) }, "edit")))),
      Object.keys(groups).length ? h("h3", {}, "Add a new module") : null,
      Object.entries(groups).map(([group, entries]) => h("div", { class: "wf-group" },
        h("h4", {}, group),
        h("ul", { class: "wf-entries", "aria-label": group }, entries.map((entry) => h("li", {},
          h("button", {
            class: "wf-entry", draggable: "true", "data-entry": entry.id, title: entry.description,
            "aria-label": `Insert: ${entry.label}`,
            ondragstart: (e) => e.dataTransfer.setData("application/x-wf-palette", JSON.stringify({ entry: entry.id })),
            onclick: () => this.insertFrom({ entry: entry.id }),
          }, entry.label)))))),
    ];
  }

  /** Insert a step from the palette: an existing module ({module}) or a palette entry ({entry}). */
  insertFrom(what, point = null) {
    const at = point || this.insertionPoint();
    let step;
    if (what.entry === "branch") {
      step = { id: uniqueStepId(this.doc, "branch"), if: "True", then: [] };
    } else if (what.entry === "set") {
      step = { id: uniqueStepId(this.doc, "set"), set: { value: "" } };
    } else {
      let moduleName = what.module;
      let entry = null;
      if (!moduleName) {
        entry = (this.palette.entries || []).find((e) => e.id === what.entry);
        if (!entry) return;
        moduleName = moduleFor(this.doc, entry) || addModule(this.doc, entry);
      }
      entry = entry || this.entryOf(moduleName);
      step = { id: uniqueStepId(this.doc, moduleName), module: moduleName };
      const defaults = {};
      for (const p of (entry && entry.params) || []) {
        if (p.name !== "robot" && p.default !== undefined && p.default !== null) defaults[p.name] = p.default;
      }
      if (Object.keys(defaults).length) step.with = defaults;
      if (entry && entry.save) step.save = step.id; // a look-up is read by later steps under its name
    }
    const path = insertStep(this.doc, at.list, at.index, step);
    this.selected = path;
    this.slot = null;
    this.editingModule = null;
    this.say(`Step ${step.id} inserted.`);
    this.changed();
    const first = this.sideEl.querySelector("[data-field^='with.'], [data-field='if'], [data-field^='set.']");
    (first || this.sideEl.querySelector("[data-field='id']"))?.focus();
  }

  editModule(name) {
    this.editingModule = name;
    this.selected = null;
    if (this.tab !== "process" && this.tab !== "scenario") this.tab = "process";
    this.renderAll();
    this.sideEl.querySelector(".wf-form input, .wf-form select")?.focus();
  }

  /** One labelled form field typed from a palette parameter; set(value) is called on every input. */
  field(param, value, set, key, inherited) {
    const id = `wf-f-${key.replace(/[^A-Za-z0-9_-]/g, "-")}`;
    const errId = `${id}-err`;
    const common = { id, "data-field": key, "aria-describedby": `${id}-help ${errId}` };
    let input;
    const choices = param.type === "robot" ? (this.palette.robots || []).map((r) => r.name)
      : param.type === "ruleset" ? this.palette.rulesets || []
        : param.type === "ontology_value" ? (this.palette.ontology_values || []).map((v) => v.name)
          : param.choices;
    if (param.type === "boolean") {
      input = h("input", { ...common, type: "checkbox", checked: !!value, onchange: (e) => set(e.target.checked) });
    } else if (choices && choices.length) {
      const known = value === undefined || value === "" || choices.includes(value);
      const label = (c) => {
        if (param.type !== "ontology_value") return String(c);
        const v = (this.palette.ontology_values || []).find((x) => x.name === c);
        return v ? `${c} = ${v.value}` : c;
      };
      input = h("select", { ...common, onchange: (e) => set(e.target.value) },
        param.required ? null : h("option", { value: "" }, inherited !== undefined ? `(module default: ${inherited})`
          : param.default !== undefined && param.default !== null ? `(default: ${param.default})` : "(none)"),
        known ? null : h("option", { value: String(value), selected: true }, `${value} (not known)`),
        choices.map((c) => h("option", { value: String(c), selected: c === value }, label(c))));
      if (param.required && (value === undefined || value === "")) input.value = "";
    } else {
      input = h("input", {
        ...common, type: "text", value: value === undefined || value === null ? "" : String(value),
        placeholder: inherited !== undefined ? `module default: ${inherited}` : param.type === "number" ? "a number or ${…}" : "",
        oninput: (e) => {
          this.coalesce = `${pathKey(this.selected || [])}|${this.editingModule || ""}|${key}`;
          set(convert(param.type, e.target.value));
        },
      });
    }
    return h("div", { class: "field wf-field", "data-field-box": key },
      h("label", { for: id }, param.name, param.required ? h("span", { class: "req", "aria-hidden": "true" }, " *") : null),
      input,
      h("span", { class: "hint", id: `${id}-help` }, param.description || ""),
      h("span", { class: "wf-field-error", id: errId, role: "alert" }));
  }

  /** A set step's variables: a name and a value each (text, number, true/false or ``${…}``). */
  variablesFields(step, update) {
    const rows = Object.entries(step.set || {}).map(([name, value]) => {
      const errorEl = h("span", { class: "wf-field-error", role: "alert" });
      const nameEl = h("input", { type: "text", value: name, "aria-label": `Name of variable ${name}`, "data-field": `set.${name}`,
        onchange: (e) => {
          const problem = renameVariable(step, name, e.target.value.trim());
          if (problem) {
            errorEl.textContent = problem;
            return e.target.focus();
          }
          update(() => {});
          this.renderSide();
          this.sideEl.querySelector(`[aria-label="Value of variable ${CSS.escape(e.target.value.trim())}"]`)?.focus();
        } });
      const valueEl = h("input", { type: "text", value: variableText(value), "aria-label": `Value of variable ${name}`,
        placeholder: "text, a number, true/false or ${…}",
        oninput: (e) => {
          this.coalesce = `${pathKey(this.selected || [])}|set.${name}`;
          update((s) => { s.set[name] = variableValue(e.target.value); });
        } });
      const removeEl = h("button", { class: "secondary small", type: "button", "aria-label": `Remove variable ${name}`,
        onclick: () => { update((s) => { delete s.set[name]; }); this.renderSide(); } }, "✕");
      return h("div", { class: "wf-variable", "data-field-box": `set.${name}` }, nameEl, h("span", { "aria-hidden": "true" }, "="),
        valueEl, removeEl, errorEl);
    });
    const add = () => {
      const name = newVariableName(step);
      update((s) => { s.set = { ...(s.set || {}), [name]: "" }; });
      this.renderSide();
      this.sideEl.querySelector(`[aria-label="Name of variable ${CSS.escape(name)}"]`)?.select();
    };
    return h("fieldset", { class: "wf-variables", "data-field-box": "set" }, h("legend", {}, "Variables it sets"), rows,
      h("button", { class: "secondary small", type: "button", onclick: add }, "+ Add a variable"),
      h("p", { class: "hint" }, "Later steps read them as ${name}. A value is a text, a number, true/false, or an expression such as ${len(input.orders)}."));
  }

  stepForm(path) {
    const step = getIn(this.doc, path);
    const update = (fn) => { fn(step); this.changed({ keepForm: true }); };
    const setKey = (key) => (value) => update((s) => { if (value === undefined || value === "") delete s[key]; else s[key] = value; });
    const stepParams = Object.fromEntries((this.palette.step_params || []).map((p) => [p.name, p]));
    const kind = step.module ? "module" : step.if !== undefined ? "branch" : step.process ? "process" : "set";
    const parts = [h("h2", {}, `Step “${step.id || "?"}”`), h("p", { class: "hint" }, `In the ${listName(this.doc, path.slice(0, -1))}.`),
      h("div", { class: "wf-step-problem", role: "alert" }),
      this.field(stepParams.id || { name: "id", type: "name", required: true }, step.id, setKey("id"), "id")];
    if (kind === "module") {
      const modules = Object.keys(this.doc.modules || {});
      parts.push(this.field({ name: "module", type: "module", required: true, choices: modules, description: "Which module this step runs." },
        step.module, (v) => { update((s) => { s.module = v; }); this.renderSide(); }, "module"));
      const module = (this.doc.modules || {})[step.module] || {};
      if (module.kind === "ros_service" && module.service) {
        // Which robot: the robots that offer this service; choosing one uses (or adds) its module.
        const service = String(module.service).split("/").pop();
        const robots = (this.palette.robots || []).filter((r) => r.services && r.services[service]).map((r) => r.name);
        const robot = (module.params || {}).robot || module.actor;
        parts.push(this.field({ name: "robot", type: "string", required: true, choices: robots,
          description: "The robot that does it (each robot has its own module for this service)." }, robot, (value) => {
          const entry = (this.palette.entries || []).find((e) => e.id === `${value}.${service}`);
          if (!entry || value === robot) return;
          const target = moduleFor(this.doc, entry) || addModule(this.doc, entry);
          step.module = target;
          this.changed();
        }, "robot"));
      }
      for (const param of this.paramsOfModule(step.module, step)) {
        if (param.name === "robot") continue; // the module's: its service is under the robot's namespace
        const inherited = (module.params || {})[param.name];
        parts.push(this.field(param, (step.with || {})[param.name], (value) => update((s) => {
          s.with = s.with || {};
          if (value === undefined || value === "") delete s.with[param.name];
          else s.with[param.name] = value;
          if (!Object.keys(s.with).length) delete s.with;
        }), `with.${param.name}`, inherited));
      }
    } else if (kind === "branch") {
      parts.push(this.field({ name: "if", type: "expression", required: true, description: "The condition; the then-arm runs when it holds, else the else-arm." },
        step.if, setKey("if"), "if"));
      parts.push(h("p", { class: "hint" }, "Add steps to the arms with their “+ add” buttons in the process view, then the palette."));
    } else if (kind === "process") {
      parts.push(this.field({ name: "process", type: "string", required: true, choices: Object.keys(this.doc.processes || {}) },
        step.process, setKey("process"), "process"));
    } else {
      parts.push(this.variablesFields(step, update));
    }
    const common = kind === "module" ? ["label", "save", "on_failure", ...(step.on_failure === "retry" ? ["retries"] : []), "timeout"]
      : kind === "process" ? ["label", "save", "on_failure"] : ["label"];
    for (const name of common) {
      const param = stepParams[name];
      if (param) parts.push(this.field(param, step[name], setKey(name), name));
    }
    return h("div", { "data-editing-step": step.id || "" }, parts);
  }

  moduleForm(name) {
    const module = (this.doc.modules || {})[name];
    if (!module) return h("p", { class: "hint" }, `There is no module “${name}” any more.`);
    const entry = this.entryOf(name);
    const update = (fn) => { fn(module); this.changed({ keepForm: true }); };
    const nameError = h("span", { class: "wf-field-error", id: "wf-module-name-err", role: "alert" });
    const nameEl = h("input", { type: "text", id: "wf-module-name", "data-field": "name", value: name,
      "aria-describedby": "wf-module-name-help wf-module-name-err",
      onchange: (e) => {
        const to = e.target.value.trim();
        const error = renameModule(this.doc, name, to);
        if (error) {
          nameError.textContent = error;
          e.target.setAttribute("aria-invalid", "true");
          return;
        }
        this.editingModule = to;
        this.say(`Module ${name} renamed to ${to}.`);
        this.changed();
        this.sideEl.querySelector("#wf-module-name")?.focus();
      } });
    const parts = [h("h2", {}, `Module “${name}”`), h("p", { class: "hint" }, `${module.kind}${module.service ? ` · ${module.service} (${module.type})` : ""}`),
      h("div", { class: "wf-step-problem", role: "alert" }),
      h("div", { class: "field wf-field" }, h("label", { for: "wf-module-name" }, "name"), nameEl,
        h("span", { class: "hint", id: "wf-module-name-help" }, "Renaming changes the steps that use it too."), nameError)];
    const actors = Object.keys(this.doc.actors || {});
    if (actors.length) {
      parts.push(this.field({ name: "actor", type: "string", choices: actors, description: "Who performs it (the scenario view's lane)." },
        module.actor, (v) => update((m) => { if (v) m.actor = v; else delete m.actor; }), "actor"));
    }
    for (const param of (entry && entry.module_params) || []) {
      if (param.type === "dispatch") { parts.push(this.dispatchEditor(module, update)); continue; }
      const onModule = param.name === "ruleset";
      const value = onModule ? module[param.name] : (module.params || {})[param.name];
      parts.push(this.field(param, value, (v) => update((m) => {
        if (onModule) m[param.name] = v;
        else {
          m.params = m.params || {};
          if (v === undefined || v === "") delete m.params[param.name]; else m.params[param.name] = v;
        }
      }), onModule ? param.name : `params.${param.name}`));
    }
    if (module.kind === "ros_service") {
      const robot = (entry?.params || []).find((p) => p.name === "robot");
      if (robot) parts.push(this.field(robot, (module.params || {}).robot, (v) => update((m) => { m.params = { ...(m.params || {}), robot: v }; }), "params.robot"));
    }
    const used = allSteps(this.doc).some(({ step }) => step && step.module === name)
      || Object.values(this.doc.modules || {}).some((m) => Object.values(m.dispatch || {}).includes(name));
    parts.push(h("div", { class: "buttons" },
      h("button", { class: "primary", onclick: () => this.insertFrom({ module: name }) }, `Insert a ${name} step`),
      used ? null : h("button", { class: "secondary", "aria-label": `Remove module ${name} (no step uses it)`, onclick: () => {
        delete this.doc.modules[name];
        this.editingModule = null;
        this.say(`Module ${name} removed.`);
        this.changed();
      } }, "Remove this module"),
      h("button", { class: "secondary", onclick: () => { this.editingModule = null; this.renderSide(); } }, "Close")));
    return h("div", { "data-editing-module": name }, parts);
  }

  dispatchEditor(module, update) {
    const modules = Object.keys(this.doc.modules || {});
    const rows = Object.entries(module.dispatch || {});
    const actionEl = h("input", { type: "text", id: "wf-dispatch-action", "aria-label": "Rule action (e.g. say)", placeholder: "action, e.g. say" });
    const targetEl = h("select", { id: "wf-dispatch-module", "aria-label": "Module that performs it" }, modules.map((m) => h("option", { value: m }, m)));
    return h("fieldset", { class: "wf-dispatch" }, h("legend", {}, "Rule actions performed by modules"),
      rows.length ? h("ul", {}, rows.map(([action, target]) => h("li", {}, `${action} → ${target} `,
        h("button", { class: "link", "aria-label": `Remove action ${action}`, onclick: () => { update((m) => { delete m.dispatch[action]; }); this.renderSide(); } }, "remove"))))
        : h("p", { class: "hint" }, "None yet."),
      h("div", { class: "wf-dispatch-add" }, actionEl, " → ", targetEl,
        h("button", { class: "secondary", onclick: () => {
          const action = actionEl.value.trim();
          if (!action) return actionEl.focus();
          update((m) => { m.dispatch = { ...(m.dispatch || {}), [action]: targetEl.value }; });
          this.renderSide();
        } }, "Add action")));
  }

  /** Put each problem next to its field in the open form. */
  markFieldErrors() {
    const form = this.sideEl.querySelector(".wf-form");
    if (!form) return;
    for (const box of form.querySelectorAll(".wf-field-error")) box.textContent = "";
    for (const input of form.querySelectorAll("[aria-invalid]")) input.removeAttribute("aria-invalid");
    const general = form.querySelector(".wf-step-problem");
    if (general) general.textContent = "";
    const stepPath = this.selected;
    for (const p of this.allProblems()) {
      const where = p.client ? { stepPath: p.stepPath, field: p.field } : locateProblem(this.doc, p);
      const mine = this.editingModule ? where.module === this.editingModule : samePath(where.stepPath, stepPath);
      if (!mine) continue;
      const key = this.editingModule && where.field && !["actor", "ruleset", "dispatch"].includes(where.field.split(".")[0]) ? `params.${where.field}` : where.field;
      const input = form.querySelector(`[data-field="${CSS.escape(key)}"]`);
      if (input) {
        input.setAttribute("aria-invalid", "true");
        form.querySelector(`[data-field-box="${CSS.escape(key)}"] .wf-field-error`).textContent = p.message;
      } else if (general) general.textContent = `${where.field ? `${where.field}: ` : ""}${p.message}`;
    }
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

  // ------------------------------------------------------------------ versions, diff, rollback

  async renderVersions() {
    fill(this.panelEl, h("p", { class: "muted" }, "Loading the versions…"));
    let versions;
    try {
      versions = await api("GET", wfPath(this.name, "/versions"));
    } catch (err) {
      fill(this.panelEl, h("div", { class: "message error", role: "alert" }, err.message));
      return;
    }
    versions = versions.slice().sort((a, b) => b.version - a.version);
    const pick = (id, label, chosen) => h("select", { id, "aria-label": label },
      versions.map((v) => h("option", { value: v.version, selected: v.version === chosen }, `version ${v.version}`)));
    const fromEl = pick("wf-diff-from", "Compare version", versions[1]?.version ?? versions[0]?.version);
    const toEl = pick("wf-diff-to", "with version", versions[0]?.version);
    const diffEl = h("div", { "data-testid": "wf-diff" });
    fill(this.panelEl, h("div", { class: "wf-versions" },
      h("div", { class: "compare" }, h("label", { for: "wf-diff-from" }, "Compare "), fromEl, h("label", { for: "wf-diff-to" }, " with "), toEl,
        h("button", { class: "secondary", onclick: () => this.diff(Number(fromEl.value), Number(toEl.value), diffEl) }, "Compare")),
      diffEl,
      h("table", { "data-testid": "wf-versions" }, h("thead", {}, h("tr", {}, ["Version", "Saved", "By", "Comment", ""].map((t) => h("th", { scope: "col" }, t)))),
        h("tbody", {}, versions.map((v) => h("tr", { class: v.version === this.version ? "live-row" : "", "data-version": v.version },
          h("td", { class: "num" }, String(v.version), v.version === this.version ? h("span", { class: "badge live" }, " live") : null),
          h("td", {}, when(v.deployed_at || v.updated_at)), h("td", {}, v.author || ""), h("td", {}, v.comment || ""),
          h("td", {}, v.version === this.version || !this.ctx.isAuthor() ? null
            : h("button", { class: "secondary", "aria-label": `Roll back to version ${v.version}`, onclick: () => this.rollback(v.version) }, "Roll back to this"))))))));
  }

  async diff(from, to, diffEl) {
    try {
      const [a, b] = await Promise.all([api("GET", wfPath(this.name, `/versions/${from}`)), api("GET", wfPath(this.name, `/versions/${to}`))]);
      const host = h("div", { class: "merge-host" });
      const setup = [basicSetup, EditorState.readOnly.of(true), EditorView.editable.of(false), languageFor("x.yaml")];
      fill(diffEl, h("p", {}, a.text === b.text ? `Versions ${from} and ${to} are the same.` : `Left: version ${from} · right: version ${to}`), host);
      new MergeView({ a: { doc: a.text, extensions: setup }, b: { doc: b.text, extensions: setup }, parent: host, collapseUnchanged: { margin: 3, minSize: 6 } });
    } catch (err) {
      fill(diffEl, h("div", { class: "message error", role: "alert" }, `Cannot compare: ${err.message}`));
    }
  }

  async rollback(version) {
    if (this.dirty && !window.confirm("Rolling back discards your unsaved changes. Go on?")) return;
    try {
      const result = await api("POST", wfPath(this.name, "/rollback"), { version, comment: `rollback to version ${version}` });
      this.ctx.flash("ok", `Rolled back: version ${result.version} is live again.`);
      this.ctx.navigate(this.ctx.href("workflows", this.name, "tab=versions"), true);
    } catch (err) {
      fill(this.saveMsgEl, h("div", { class: "message error", role: "alert" }, `Not rolled back: ${err.message}`));
    }
  }

  // ------------------------------------------------------------------ saving

  async flush() {
    this.checkSoon.cancel();
    if (this.yamlCheck) this.yamlCheck.cancel();
    await this.check(this.tab === "yaml" && this.yamlView ? { text: this.yamlView.state.doc.toString() } : undefined);
  }

  async save(baseVersion = this.base) {
    await this.flush();
    if (!this.dirty) {
      fill(this.saveMsgEl, h("div", { class: "message info", role: "status" }, "Nothing to save: this is the live version."));
      return;
    }
    if (this.clientProblems.length) {
      fill(this.saveMsgEl, h("div", { class: "message error", role: "alert" },
        `Not saved: ${this.describeProblem(this.clientProblems[0]).text}. Nothing changed live.`));
      return;
    }
    this.saveBtn.disabled = true;
    try {
      const result = await api("PUT", wfPath(this.name), { text: this.text, comment: this.commentEl.value, base_version: baseVersion });
      this.version = result.version;
      this.base = result.version;
      this.savedText = this.text;
      this.keepDraft();
      this.commentEl.value = "";
      fill(this.saveMsgEl, h("div", { class: "message ok", role: "status" }, `Saved: version ${result.version} is live. The next run uses it.`));
      this.renderAll();
    } catch (err) {
      if (err.status === 409) this.conflict(err.body && err.body.current);
      else if (err.status === 422) {
        this.problems = (err.body && err.body.problems) || [];
        this.renderStatus();
        fill(this.saveMsgEl, h("div", { class: "message error", role: "alert" },
          `Not saved: ${this.problems.length} problem(s), listed above. Nothing changed live; your edits are kept.`));
      } else fill(this.saveMsgEl, h("div", { class: "message error", role: "alert" }, `Not saved: ${err.message} Your edits are kept.`));
    } finally {
      this.saveBtn.disabled = false;
    }
  }

  conflict(current) {
    fill(this.saveMsgEl, h("div", { class: "message error", role: "alert", "data-testid": "wf-conflict" },
      h("p", {}, `Not saved: someone else saved version ${current} of this workflow while you were editing version ${this.base}. `
        + "Nothing changed live, and your edits are still here."),
      h("div", { class: "buttons" },
        h("button", { class: "secondary", onclick: (e) => this.compareWithLive(current, e.currentTarget) }, `Compare my edits with version ${current}`),
        h("button", { class: "danger", onclick: () => { this.version = current; this.base = current; this.save(current); } }, `Save mine over version ${current}`))));
  }

  /** Under the conflict message: version `current` (left) against the edits (right). */
  async compareWithLive(current, button) {
    button.disabled = true;
    try {
      const theirs = await api("GET", wfPath(this.name, `/versions/${current}`));
      const host = h("div", { class: "merge-host", "data-testid": "wf-conflict-diff" });
      const setup = [basicSetup, EditorState.readOnly.of(true), EditorView.editable.of(false), languageFor("x.yaml")];
      this.saveMsgEl.append(h("p", { class: "hint" }, `Left: version ${current} (live) · right: your edits`), host);
      new MergeView({ a: { doc: theirs.text, extensions: setup }, b: { doc: this.text, extensions: setup }, parent: host,
        collapseUnchanged: { margin: 3, minSize: 6 } });
    } catch (err) {
      this.saveMsgEl.append(h("div", { class: "message error", role: "alert" }, `Cannot compare: ${err.message}`));
    }
  }

  discard() {
    this.checkSoon.cancel();
    if (this.doc && (this.dirty || this.undoStack.length)) {
      this.undoStack.push(JSON.stringify(this.doc)); // Undo brings the discarded edits back
      this.redoStack = [];
    }
    this.text = this.savedText;
    this.base = this.version;
    this.keepDraft();
    this.doc = null;
    this.selected = null;
    this.editingModule = null;
    fill(this.saveMsgEl);
    this.check({ text: this.text }).then(() => this.renderAll());
  }

  // ------------------------------------------------------------------ running

  renderRun() {
    const inputsEl = h("textarea", { id: "wf-inputs", rows: 3, "aria-label": "Run inputs (JSON; empty: the workflow's defaults)",
      placeholder: "{} — the workflow's default inputs" });
    this.traceEl = h("ol", { class: "wf-trace", "data-testid": "wf-trace", "aria-live": "polite", "aria-label": "Run trace" });
    this.runMsgEl = h("div", { "aria-live": "polite" });
    fill(this.runEl, h("h2", {}, "Run on the simulated robots"),
      h("p", { class: "hint" }, "Runs the saved (live) version; the trace shows each step as it happens."),
      h("details", {}, h("summary", {}, "Inputs"), h("label", { for: "wf-inputs", class: "hint" }, "JSON object, e.g. {\"orders\": []}"), inputsEl),
      h("div", { class: "buttons" },
        h("button", { class: "primary", "data-testid": "wf-run", onclick: () => this.run(inputsEl.value) }, "Run the live version"),
        this.ctx.isAuthor() ? h("button", { class: "secondary", "data-testid": "wf-try", onclick: () => this.run(inputsEl.value, true) },
          "Try my unsaved edits") : null),
      this.runMsgEl, this.traceEl);
  }

  /** Run the live version, or (`trial`) the edited text without saving it; follow it step by step. */
  async run(inputsText, trial = false) {
    let inputs = {};
    if (inputsText.trim()) {
      try {
        inputs = JSON.parse(inputsText);
        if (!inputs || typeof inputs !== "object" || Array.isArray(inputs)) throw new Error("not an object");
      } catch (err) {
        fill(this.runMsgEl, h("div", { class: "message error", role: "alert" }, `Inputs: not a JSON object (${err.message}).`));
        return;
      }
    }
    this.timers.forEach(clearTimeout);
    this.timers = [];
    clearInterval(this.revealTimer);
    this.trace = [];
    this.markTrace();
    fill(this.traceEl);
    fill(this.runMsgEl, h("p", { class: "muted", role: "status" }, this.dirty
      ? (trial ? "Trying your unsaved edits (nothing is saved or made live)…" : `Running the saved version ${this.version} (your unsaved changes are not run)…`)
      : `Running version ${this.version}…`));
    let started;
    try {
      if (trial) await this.flush();
      started = trial ? await api("POST", "/api/workflows/try", { text: this.text, inputs })
        : await api("POST", wfPath(this.name, "/run"), { inputs, wait: false });
    } catch (err) {
      const why = err.status === 422 ? "your edits have problems (listed above); fix them, then try again." : err.message;
      fill(this.runMsgEl, h("div", { class: "message error", role: "alert" }, `The run could not start: ${why}`));
      return;
    }
    // The steps arrive as the robots do them (polling the run); they are shown one at a time.
    const runId = started.run_id;
    this.runId = runId;
    const queue = [];
    let received = 0;
    let final = null;
    const poll = async () => {
      if (this.disposed || this.runId !== runId) return;
      let data;
      try {
        data = await api("GET", `/api/workflows/runs/${encodeURIComponent(runId)}`);
      } catch (err) {
        final = { status: "failed", error: `the run could not be followed: ${err.message}`, steps: [] };
        return;
      }
      const steps = data.steps || [];
      queue.push(...steps.slice(received));
      received = Math.max(received, steps.length);
      if (data.status === "running") this.timers.push(setTimeout(poll, RUN_POLL_MS));
      else final = data;
    };
    let shown = 0;
    this.revealTimer = setInterval(() => {
      if (this.disposed || this.runId !== runId) return clearInterval(this.revealTimer);
      if (queue.length) {
        this.showRecord(queue.shift(), shown);
        shown += 1;
      } else if (final) {
        clearInterval(this.revealTimer);
        this.markTrace();
        fill(this.runMsgEl, h("div", { class: `message ${final.status === "succeeded" ? "ok" : "error"}`, role: "status", "data-testid": "wf-run-status" },
          final.status === "succeeded" ? `Run ${runId} of ${trial ? "your unsaved edits" : `version ${final.version}`} succeeded: ${shown} steps.`
            : `Run ${runId} failed: ${final.error}`));
      }
    }, TRACE_STEP_MS);
    poll();
  }

  showRecord(record, index) {
    if (this.disposed) return;
    const p = record.params || {};
    const looked = record.kind === "ontology_value" && record.output && record.output.value !== undefined;
    const what = looked ? `${p.name} = ${record.output.value}`
      : p.text ?? p.name ?? p.location ?? p.prompt ?? (p.seconds !== undefined ? `${p.seconds} s` : "");
    const coords = p.x !== undefined ? `(${p.x}, ${p.y})` : "";
    this.traceEl.append(h("li", { class: `wf-record ${record.status}`, "data-step": record.step_id, "data-index": index },
      h("span", { class: "mark" }, record.status === "ok" ? "✓" : record.status === "skipped" ? "–" : "✗"),
      h("b", {}, record.step_id), ` · ${record.module || record.type}${record.via ? ` (via ${record.via})` : ""}`,
      record.actor ? h("span", { class: "muted" }, ` · ${record.actor}`) : null,
      what || coords ? h("span", { class: "wf-said" }, `: ${what || coords}`) : null,
      record.error ? h("span", { class: "wf-error" }, ` — ${record.error}`) : null));
    this.trace = (this.trace || []).concat([record]);
    this.markTrace(record.step_id);
  }

  /** Highlight the steps of the process view the run went through (and the current one). */
  markTrace(current = null) {
    const done = new Set((this.trace || []).map((r) => r.step_id));
    for (const li of this.panelEl.querySelectorAll("li.wf-step")) {
      li.classList.toggle("ran", done.has(li.dataset.step));
      li.classList.toggle("running", !!current && li.dataset.step === current);
    }
  }
}

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

function convert(type, raw) {
  const text = raw.trim();
  if (text === "") return undefined;
  if ((type === "number" || type === "integer") && /^-?\d+(\.\d+)?$/.test(text)) return Number(text);
  return raw;
}

function authHeaders() {
  const token = getToken();
  return token ? { Authorization: `Bearer ${token}` } : {};
}
