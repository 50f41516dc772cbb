// The workflow editor's forms: one labelled field per parameter typed from the palette, the step and
// module forms, a set step's variables, a rule module's actions, and each problem next to its
// field. Mixed into WorkflowEditor (workflow-view.js).

import { h, fill } from "./dom.js";
import { describeReferences, insertReference, valueChoices } from "./workflow-values.js";
import {
  getIn, allSteps, listName, moduleFor, addModule, locateProblem, samePath, renameModule, variableValue,
  variableText, renameVariable, newVariableName, pathKey,
} from "./workflow-model.js";

/** A field's text as the YAML value: numbers for number fields, nothing for an empty field. */
function convert(type, raw) {
  const text = raw.trim();
  if (text === "") return undefined;
  if ((type === "number" || type === "integer") && /^-?\d+(\.\d+)?$/.test(text)) return Number(text);
  return raw;
}

export const formMethods = {
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
          this.showReferences(usesEl, e.target.value);
        },
      });
    }
    const usesEl = h("span", { class: "hint wf-uses", "aria-live": "polite" });
    const picker = input.tagName === "INPUT" && input.type === "text" && key.startsWith("with.") && this.selected
      ? this.valuePicker(id, param, input, (text) => { set(convert(param.type, text)); this.showReferences(usesEl, text); }) : null;
    if (picker) this.showReferences(usesEl, input.value);
    return h("div", { class: "field wf-field", "data-field-box": key },
      h("label", { for: id }, param.name, param.required ? h("span", { class: "req", "aria-hidden": "true" }, " *") : null),
      input, picker, usesEl,
      h("span", { class: "hint", id: `${id}-help` }, param.description || ""),
      h("span", { class: "wf-field-error", id: errId, role: "alert" }));
  },

  /** "Pick a value for location": what the run is given and what earlier steps found, in words;
   *  the chosen one goes into the field as its reference (at the cursor, or as the whole value). */
  valuePicker(id, param, input, changed) {
    const choices = valueChoices(this.doc, this.selected);
    if (!choices.length) return null;
    let caret = null;
    input.addEventListener("blur", () => { caret = input.selectionStart; });
    const groups = [["given", "What the run is given"], ["found", "What earlier steps found"]]
      .map(([group, label]) => [label, choices.map((c, i) => [c, i]).filter(([c]) => c.group === group)])
      .filter(([, mine]) => mine.length);
    const option = ([c, i]) => h("option", { value: String(i) }, c.label);
    const select = h("select", { id: `${id}-pick`, class: "wf-pick", onchange: () => {
      const picked = choices[Number(select.value)];
      select.value = "";
      if (!picked) return;
      input.value = insertReference(input.value, picked.ref, caret);
      caret = null;
      this.coalesce = null;
      changed(input.value);
      this.say(`${param.name}: ${picked.label}.`);
    } }, h("option", { value: "" }, "Pick a value…"),
    groups.length === 1 ? groups[0][1].map(option) : groups.map(([label, mine]) => h("optgroup", { label }, mine.map(option))));
    return h("div", { class: "wf-pick-row" }, h("label", { for: `${id}-pick` }, `Pick a value for ${param.name}`), select);
  },

  /** Under a field: the values it refers to in words, and a name that is neither given nor found. */
  showReferences(el, text) {
    const { known, unknown } = describeReferences(text, valueChoices(this.doc, this.selected));
    const given = Object.keys(this.doc.inputs || {});
    fill(el, known.length ? `Uses ${known.join(", ")}.` : "",
      unknown.length ? h("span", { class: "wf-unknown" }, ` “${unknown.join("”, “")}” is not among what the run is given`
        + `${given.length ? ` (${given.join(", ")})` : ""} or what earlier steps found: the run must be given it, or pick a value from the menu.`) : "");
  },

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
  },

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
  },

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
  },

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
  },

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
  },
};
