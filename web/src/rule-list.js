// The rules as a list of what they do: each rule of the rule set by name with its sentences in the
// owner's words (the .dslr sentences, a decision table's row), what feeds the rule set (a stream
// query, a workflow step, the ROS service), and a search field that filters the list as you type.
// Self-contained: mountRuleList(host, options) -> {load, refresh, visible, dispose}; load() once the
// editors hold the files.

import { h, fill, debounce } from "./dom.js";
import { api, rulesetPath } from "./api.js";
import "./owner.css";

const REFRESH_DELAY_MS = 600;

/** The words of `query` (lower case); a rule matches when each word is in its name or sentences. */
export function matches(rule, query) {
  const words = query.toLowerCase().split(/\s+/).filter(Boolean);
  if (!words.length) return true;
  const text = [rule.name, ...(rule.when || []), ...(rule.then || [])].join(" ").toLowerCase();
  return words.every((w) => text.includes(w));
}

/** The sentences worth showing first: what the rule does (its then-part), else its conditions. */
function sentencesOf(rule) {
  return (rule.then && rule.then.length ? rule.then : rule.when) || [];
}

/**
 * Mount the rule list in `host`.
 * options: name (rule set), files() -> {name: text} (the draft), goTo(rule) (open it in the
 *          editor), onSearch(text) (the search words changed: mark them in the editor), tools (a
 *          node for the head's right end: the rule tools' buttons).
 */
export function mountRuleList(host, { name, files, goTo = () => {}, onSearch = () => {}, tools = null }) {
  const usedEl = h("p", { class: "used-by", "data-testid": "used-by" });
  const search = h("input", { type: "search", class: "rule-search", "data-testid": "rule-search",
    placeholder: "Find a rule or what it says, e.g. Two seats", "aria-label": "Find a rule or a sentence",
    oninput: () => show() });
  const countEl = h("span", { class: "rule-count muted", "aria-live": "polite" });
  const listEl = h("ul", { class: "rule-list", "data-testid": "rule-list" });
  fill(host, h("div", { class: "card rules-outline" },
    h("div", { class: "outline-head" }, h("h2", {}, "What these rules do"), countEl, tools),
    usedEl,
    h("label", { class: "search-field" }, h("span", {}, "Search"), search),
    listEl));
  let rules = [];
  let usedBy = null;
  let seq = 0;

  async function refresh() {
    const mine = ++seq;
    try {
      const outline = await api("POST", rulesetPath(name, "/outline"), { files: files() });
      if (mine !== seq) return;
      rules = outline.rules || [];
      usedBy = outline.used_by || [];
    } catch {
      if (mine !== seq) return; // keep the last good list
    }
    showUsed();
    show();
  }

  function showUsed() {
    if (!usedBy) return;
    fill(usedEl, usedBy.length
      ? [h("b", {}, "Used by: "), usedBy.map((u, i) => [i ? "; " : "", u.text])]
      : h("span", { class: "muted" }, "Nothing feeds this rule set yet: no stream query, workflow step or robot service fires it."));
  }

  function show() {
    const query = search.value;
    onSearch(query.trim());
    const shown = rules.filter((r) => matches(r, query));
    countEl.textContent = query.trim() ? `${shown.length} of ${rules.length} rules match “${query.trim()}”` : `${rules.length} rules`;
    fill(listEl, shown.map((rule) => h("li", {},
      h("button", { class: "rule-item", "data-rule": rule.name, onclick: () => goTo(rule),
        title: rule.row ? `${rule.file}, row ${rule.row}` : `${rule.file}, line ${rule.line}` },
        h("span", { class: "rule-name" }, rule.name),
        h("span", { class: "rule-sentences" }, sentencesOf(rule).map((s) => h("span", { class: "sentence" }, s)))))));
    if (query.trim() && !shown.length) listEl.append(h("li", { class: "none muted" }, "No rule says that."));
  }

  const later = debounce(refresh, REFRESH_DELAY_MS);
  return {
    load: refresh,
    refresh: later,
    /** The rules currently listed (after the search). */
    visible: () => rules.filter((r) => matches(r, search.value)),
    /** Every rule of the last outline (whatever the search). */
    all: () => rules,
    dispose() {
      seq++;
      later.cancel();
    },
  };
}
