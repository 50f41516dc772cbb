// The Rules view's list of rules by name with its search, and (authors) the Replace… and + New rule
// tools under it. Mixed into RulesView (rules-view.js).

import { h } from "./dom.js";
import { scrollToLine } from "./editor.js";
import { setFind } from "./find-highlight.js";
import { mountRuleList } from "./rule-list.js";
import { mountRuleTools } from "./rule-tools.js";

export const searchMethods = {
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
  },

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
      deploy: () => this.deploy(),
    });
    return { host, buttons: tools.buttons };
  },

  /** Mark the search words in every editor and bring the first rule that matches into view. */
  searchEditors(text) {
    for (const view of Object.values(this.views)) setFind(view, text);
    if (!text || !this.ruleList) return;
    const first = this.ruleList.visible().find((r) => r.line && this.views[r.file]);
    if (!first) return;
    if (first.file !== this.active) this.select(first.file);
    scrollToLine(this.views[first.file], first.line, "start");
  },
};
