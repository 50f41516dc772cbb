// The workflow editor's side column and palette: which form is open, the palette of modules (one row
// each, plain names) and inserting a step from it. Mixed into WorkflowEditor (workflow-view.js).

import { h, fill } from "./dom.js";
import { paletteRows, kindWord } from "./palette-entries.js";
import { getIn, uniqueStepId, insertStep, moduleFor, addModule } from "./workflow-model.js";

export const paletteMethods = {
  // ------------------------------------------------------------------ palette (side column)

  entryOf(moduleName) {
    const module = (this.doc.modules || {})[moduleName];
    if (!module) return null;
    const entries = this.palette.entries || [];
    if (module.kind === "ros_service") {
      return entries.find((e) => e.kind === "ros_service" && e.module.service === module.service)
        || entries.find((e) => e.kind === "ros_service" && e.module.type === module.type) || null;
    }
    return entries.find((e) => e.kind === module.kind) || null;
  },

  /** The typed parameters of a module's steps: from the palette, else (a module the palette does not
   *  describe, e.g. a topic) text fields for the parameters the module and the step already use. */
  paramsOfModule(moduleName, step = null) {
    const entry = this.entryOf(moduleName);
    if (entry) return entry.params || [];
    const module = (this.doc.modules || {})[moduleName] || {};
    const names = new Set([...Object.keys(module.params || {}), ...Object.keys((step && step.with) || {})]);
    names.delete("robot");
    return [...names].map((name) => ({ name, type: "string", description: "" }));
  },

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
  },

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
  },

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
  },

  editModule(name) {
    this.editingModule = name;
    this.selected = null;
    if (this.tab !== "process" && this.tab !== "scenario") this.tab = "process";
    this.renderAll();
    this.sideEl.querySelector(".wf-form input, .wf-form select")?.focus();
  },
};
