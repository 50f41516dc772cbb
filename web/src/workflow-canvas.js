// The workflow editor's canvas: the process view (services, processes, their steps and branch arms),
// with selection, keyboard moves, drag and drop and the insertion point of new steps. Mixed into
// WorkflowEditor (workflow-view.js), whose state (doc, selected, slot) these methods read and change.

import { h, fill } from "./dom.js";
import { kindWord } from "./palette-entries.js";
import {
  getIn, removeStep, shiftStep, moveStep, listName, stepSummary, samePath, renameProcess, removeProcess,
  nameProblem, pathKey,
} from "./workflow-model.js";
import { referencesInWords, valueChoices } from "./workflow-values.js";

export const canvasMethods = {
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
  },

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
  },

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
  },

  startRename(name) {
    this.renaming = name;
    this.renderProcessView();
    this.panelEl.querySelector(".wf-rename input")?.select();
  },

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
  },

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
  },

  /** Removes a process with its steps, and from the services that list it (Ctrl+Z undoes). */
  removeProcessOf(name) {
    const steps = removeProcess(this.doc, name);
    const inIt = (path) => path && path[0] === "processes" && path[1] === name;
    if (inIt(this.selected)) this.selected = null;
    if (this.slot && inIt(this.slot.list)) this.slot = null;
    this.say(`Process ${name} removed with its ${steps} step${steps === 1 ? "" : "s"}; Undo (Ctrl+Z) brings it back.`);
    this.changed();
  },

  stepList(listPath, steps) {
    const label = listName(this.doc, listPath);
    const slotActive = this.slot && samePath(this.slot.list, listPath) && !this.slot.start;
    const startActive = this.slot && samePath(this.slot.list, listPath) && this.slot.start;
    // a list with steps is also entered at its start (a step before its first one, in one click)
    const start = steps.length ? h("button", {
      class: `wf-slot wf-slot-start${startActive ? " active" : ""}`, "aria-pressed": String(!!startActive),
      "data-slot-start": pathKey(listPath), "aria-label": `Add new steps at the start of the ${label}`,
      onclick: () => this.chooseSlot(listPath, 0, { start: true }),
      ondragover: (e) => this.dragOver(e), ondragleave: (e) => e.currentTarget.classList.remove("drop"),
      ondrop: (e) => this.drop(e, listPath, 0),
    }, `+ add at the start of the ${label}`) : null;
    return h("div", { class: "wf-list" }, start,
      h("ol", { class: "wf-steps", "aria-label": `Steps of ${label}` }, steps.map((step, i) => this.stepItem([...listPath, i], step))),
      h("button", {
        class: `wf-slot${slotActive ? " active" : ""}`, "aria-pressed": String(!!slotActive), "data-slot": pathKey(listPath),
        "aria-label": `Add new steps at the end of the ${label}`,
        onclick: () => this.chooseSlot(listPath, steps.length),
        ondragover: (e) => this.dragOver(e), ondragleave: (e) => e.currentTarget.classList.remove("drop"),
        ondrop: (e) => this.drop(e, listPath, steps.length),
      }, steps.length ? `+ add at the end of the ${label}` : `+ add steps to the ${label} (empty)`));
  },

  stepItem(path, step) {
    const selected = samePath(this.selected, path);
    const id = step && step.id ? step.id : `(step ${path[path.length - 1] + 1})`;
    const kind = step.module ? ((this.doc.modules || {})[step.module] || {}).kind || "module"
      : step.if !== undefined ? "branch" : step.process ? "process" : "set";
    const summary = referencesInWords(stepSummary(step), valueChoices(this.doc, path));
    const main = h("button", {
      class: "wf-step-main", "aria-pressed": String(selected), "data-step": step.id || "",
      "aria-label": `Step ${id}: ${summary}. Alt+Arrow keys move it, Delete removes it.`,
      onclick: () => this.select(path), onkeydown: (e) => this.stepKeys(e, path),
    }, h("span", { class: `wf-kind k-${kind}` }, kindWord(kind)), h("span", { class: "wf-id" }, id),
    h("span", { class: "wf-summary", title: stepSummary(step) }, summary));
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
  },

  markStepErrors() {
    for (const li of this.panelEl.querySelectorAll("li.wf-step")) {
      const path = li.dataset.path.split("/").map((x) => (/^\d+$/.test(x) ? Number(x) : x));
      const mine = this.problemsFor(path);
      li.classList.toggle("has-error", mine.length > 0);
      const box = li.querySelector(":scope > .wf-step-errors");
      fill(box, mine.map(({ p }) => h("div", { class: "wf-error" }, this.describeProblem(p).text)));
    }
  },

  stepKeys(event, path) {
    if (event.altKey && (event.key === "ArrowUp" || event.key === "ArrowDown")) {
      event.preventDefault();
      this.shift(path, event.key === "ArrowUp" ? -1 : 1);
    } else if (event.key === "Delete") {
      event.preventDefault();
      this.remove(path);
    }
  },

  focusStep(path) {
    const li = path && this.panelEl.querySelector(`li.wf-step[data-path="${CSS.escape(pathKey(path))}"]`);
    const target = li ? li.querySelector(":scope > .wf-step-row .wf-step-main") : null;
    if (target) target.focus();
  },

  shift(path, delta) {
    const to = shiftStep(this.doc, path, delta);
    if (samePath(to, path)) return;
    this.selected = to;
    this.slot = null;
    this.say(`Step ${getIn(this.doc, to).id} moved ${delta < 0 ? "up" : "down"}.`);
    this.changed();
    this.focusStep(to);
  },

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
  },

  dragOver(event) {
    const types = [...event.dataTransfer.types];
    if (!types.includes("application/x-wf-step") && !types.includes("application/x-wf-palette")) return;
    event.preventDefault();
    event.stopPropagation();
    event.currentTarget.classList.add("drop");
  },

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
  },

  chooseSlot(listPath, index, { start = false } = {}) {
    this.slot = start ? { list: listPath, index, start } : { list: listPath, index };
    this.selected = null;
    this.renderProcessView();
    this.renderSide();
    const slot = this.panelEl.querySelector(`[data-slot${start ? "-start" : ""}="${CSS.escape(pathKey(listPath))}"]`);
    if (slot) slot.focus();
  },

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
  },

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
  },

  insertionText() {
    if (this.slot) return `at the ${this.slot.start ? "start" : "end"} of the ${listName(this.doc, this.slot.list)}`;
    if (this.selected && getIn(this.doc, this.selected)) return `${this.where === "before" ? "before" : "after"} step “${getIn(this.doc, this.selected).id}”`;
    return "at the end of the first process";
  },

  say(text) {
    if (this.liveEl) this.liveEl.textContent = text;
  },
};
