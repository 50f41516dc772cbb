// The Rules view's "Try it" panel: situations and facts, and what the robot would do with the text
// in the editor (nothing deployed). Mixed into RulesView (rules-view.js).

import { actionList, firedList } from "./actions.js";
import { api, rulesetPath } from "./api.js";
import { h, fill } from "./dom.js";
import { createEditor, setText } from "./editor.js";
import { normalizeErrors } from "./rules-common.js";

export const tryMethods = {
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
  },

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
  },

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
  },
};

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
