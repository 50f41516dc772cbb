// The owner's two rule tools beside the rule list, both driven by visible controls only (no
// keyboard shortcuts, no rule syntax): "Replace…" changes words in every rule at once (e.g. each
// "bow" becomes a "deep bow with open arms"), listing where before it changes anything; "+ New rule"
// writes a rule from sentences chosen in menus (the rule set's own phrase book), with a field for
// each blank. The logic is in rule-words.js. Self-contained: mountRuleTools(host, options) puts the
// panels in `host` and returns the two buttons, which the caller places (in the rule list's head).

import { h, fill } from "./dom.js";
import { dslEntries } from "./assist-core.js";
import { CONDITION_SCOPES, CONSEQUENCE_SCOPES } from "./checks.js";
import { defaultRuleName, fillSentence, findAll, holeProblem, isRuleText, neededConditions, newRuleProblems, ruleAt,
  ruleText, sentenceGroups, sentenceParts, sentenceShown, sentenceUse } from "./rule-words.js";

const MAX_LISTED = 8;

/**
 * Mount the tools in `host`.
 * options: files() -> {name: text} (the draft), rules() -> the outline's rules ([{name, file, line}]),
 *          replace(file, [{from, to, insert}]) (edit an editor), append(file, text) -> first line of
 *          the appended text, goTo(file, line) (show it in the editor), deploy() (optional: deploy
 *          the draft, offered as "Add the rule and deploy").
 */
export function mountRuleTools(host, options) {
  const panelEl = h("div", { class: "rule-tool-panel" });
  const replaceBtn = h("button", { class: "secondary", "aria-expanded": "false", onclick: () => open("replace") }, "Replace…");
  const newBtn = h("button", { class: "secondary", "aria-expanded": "false", onclick: () => open("new") }, "+ New rule");
  fill(host, panelEl);
  let shown = null;

  function open(which) {
    shown = shown === which ? null : which;
    replaceBtn.setAttribute("aria-expanded", String(shown === "replace"));
    newBtn.setAttribute("aria-expanded", String(shown === "new"));
    fill(panelEl, shown === "replace" ? replacePanel(options, close) : shown === "new" ? newRulePanel(options, close) : null);
    panelEl.querySelector("input")?.focus();
  }

  function close() {
    shown = null;
    replaceBtn.setAttribute("aria-expanded", "false");
    newBtn.setAttribute("aria-expanded", "false");
  }

  return { buttons: h("span", { class: "rule-tools" }, replaceBtn, newBtn), dispose: () => fill(panelEl) };
}

/** Where `find` stands in the rule texts: [{file, from, to, line}]. */
function places(files, find) {
  const out = [];
  for (const [file, text] of Object.entries(files)) {
    if (isRuleText(file)) out.push(...findAll(text, find).map((m) => ({ file, ...m })));
  }
  return out;
}

function replacePanel({ files, rules, replace, goTo }, close) {
  const findEl = h("input", { type: "text", id: "replace-find", oninput: () => show() });
  const withEl = h("input", { type: "text", id: "replace-with", oninput: () => show() });
  const foundEl = h("div", { class: "replace-found", "aria-live": "polite" });
  const doneEl = h("div", { "aria-live": "polite" });
  const goBtn = h("button", { class: "primary", disabled: true, onclick: () => doIt() }, "Replace all");

  function show() {
    fill(doneEl);
    const find = findEl.value;
    const found = find ? places(files(), find) : [];
    goBtn.disabled = !found.length || withEl.value === find;
    if (!find) return fill(foundEl, h("p", { class: "hint" }, "Type the words to change, as the rules say them (e.g. \"bow\" with its quotes)."));
    if (!found.length) return fill(foundEl, h("p", {}, "Not in the rules."));
    const all = rules();
    fill(foundEl, h("p", {}, `Found in ${found.length} ${found.length === 1 ? "place" : "places"}:`),
      h("ul", { class: "replace-places" }, found.slice(0, MAX_LISTED).map((p) => {
        const rule = ruleAt(all, p.file, p.line);
        return h("li", {}, h("button", { class: "link", onclick: () => goTo(p.file, p.line) },
          rule ? `${rule.name} (line ${p.line})` : `${p.file}, line ${p.line}`));
      }), found.length > MAX_LISTED ? h("li", { class: "muted" }, `and ${found.length - MAX_LISTED} more`) : null));
  }

  function doIt() {
    const found = places(files(), findEl.value);
    const byFile = {};
    for (const p of found) (byFile[p.file] ||= []).push({ from: p.from, to: p.to, insert: withEl.value });
    for (const [file, changes] of Object.entries(byFile)) replace(file, changes);
    fill(foundEl);
    goBtn.disabled = true;
    fill(doneEl, h("p", { class: "message ok", role: "status" },
      `✓ Replaced ${found.length} ${found.length === 1 ? "place" : "places"}. Deploy when the checks are green.`));
  }

  show();
  return h("section", { class: "card rule-tool", "aria-label": "Replace words in the rules" },
    h("h3", {}, "Replace words in every rule"),
    h("div", { class: "field" }, h("label", { for: "replace-find" }, "Find"), findEl),
    h("div", { class: "field" }, h("label", { for: "replace-with" }, "Replace with"), withEl),
    foundEl,
    h("div", { class: "buttons" }, goBtn, h("button", { class: "secondary", onclick: (e) => {
      close();
      fill(e.target.closest(".rule-tool-panel"));
    } }, "Close")),
    doneEl);
}

/** One chosen sentence: its words with a field for each blank, and a Remove button. */
function sentenceRow(entry, onRemove) {
  const values = {};
  const shown = sentenceShown(entry.sentence);
  const inputs = [];
  const parts = sentenceParts(entry.sentence).map((part) => {
    if (!part.hole) return h("span", {}, part.text);
    const input = h("input", { type: "text", class: "blank", "aria-label": `${part.hole.name} in: ${shown}`,
      placeholder: part.hole.name, oninput: (e) => { values[part.hole.name] = e.target.value; } });
    inputs.push(input);
    return input;
  });
  const el = h("li", { class: "sentence-row" }, h("span", { class: "sentence-words" }, parts),
    h("button", { class: "link", "aria-label": `Remove: ${shown}`, onclick: () => { el.remove(); onRemove(); } }, "Remove"));
  return {
    el,
    inputs,
    line: () => {
      const holes = sentenceParts(entry.sentence).filter((p) => p.hole).map((p) => p.hole);
      const problem = holes.map((hole) => holeProblem(hole, values[hole.name] || "")).find(Boolean) || "";
      return { shown, problem, text: fillSentence(entry.sentence, values) };
    },
  };
}

/** A menu of sentences in groups (most used, then the phrase book's sections); onPick(entry). */
function sentenceMenu(label, id, groups, onPick) {
  const options = groups.flatMap((g) => g.entries);
  let index = 0;
  const select = h("select", { id, onchange: () => {
    const entry = options[Number(select.value)];
    select.value = "";
    if (entry) onPick(entry);
  } }, h("option", { value: "" }, "Choose a sentence…"),
  groups.map((g) => h("optgroup", { label: g.label },
    g.entries.map((e) => h("option", { value: String(index++) }, sentenceShown(e.sentence))))));
  return h("div", { class: "field" }, h("label", { for: id }, label), select);
}

function newRulePanel({ files, rules, append, goTo, deploy }, close) {
  const current = files();
  const target = Object.keys(current).find((f) => /\.dslr$/i.test(f));
  if (!target) {
    return h("section", { class: "card rule-tool", "aria-label": "A new rule" },
      h("p", {}, "This rule set has no sentence file (.dslr) and no phrase book: a new rule here is written in the editor."));
  }
  const entries = dslEntries(current);
  const use = sentenceUse(entries, current);
  const conditions = entries.filter((e) => CONDITION_SCOPES.has(e.scope));
  const actions = entries.filter((e) => CONSEQUENCE_SCOPES.has(e.scope));
  const rows = { when: [], then: [] };
  const lists = { when: h("ol", { class: "sentences", "aria-label": "When" }), then: h("ol", { class: "sentences", "aria-label": "Then" }) };
  const nameEl = h("input", { type: "text", id: "new-rule-name", placeholder: "e.g. Offer blankets (else named after its first action)" });
  const problemsEl = h("div", { "aria-live": "polite" });
  const noteEl = h("p", { class: "hint", "aria-live": "polite" });

  function addRow(part, entry) {
    const row = sentenceRow(entry, () => { rows[part] = rows[part].filter((r) => r !== row); });
    row.entry = entry;
    rows[part].push(row);
    lists[part].append(row.el);
    return row;
  }

  /** Add a sentence, after the conditions it is about (found in the phrase book) when they are missing. */
  function pick(part, entry) {
    const needed = neededConditions(entry, rows.when.map((r) => r.entry), conditions);
    for (const condition of needed) addRow("when", condition);
    fill(noteEl, needed.length ? `Added “${needed.map((e) => sentenceShown(e.sentence)).join("”, “")}” under When: `
      + `“${sentenceShown(entry.sentence)}” is about ${needed.length === 1 ? "it" : "them"}.` : "");
    addRow(part, entry).inputs[0]?.focus();
  }

  function add({ andDeploy = false } = {}) {
    const when = rows.when.map((r) => r.line());
    const then = rows.then.map((r) => r.line());
    const existing = rules().map((r) => r.name);
    const name = nameEl.value.trim() || defaultRuleName(then.map((l) => l.text), existing); // the name is optional
    const problems = newRuleProblems(name, when, then, existing);
    if (problems.length) {
      return fill(problemsEl, h("div", { class: "message error", role: "alert" }, h("p", {}, "The rule is not added yet:"),
        h("ul", {}, problems.map((p) => h("li", {}, p)))));
    }
    const line = append(target, ruleText(name, when.map((l) => l.text), then.map((l) => l.text)));
    goTo(target, line);
    const panel = problemsEl.closest(".rule-tool-panel");
    close();
    fill(panel, h("p", { class: "message ok", role: "status" }, `✓ Rule “${name}” added at the end of ${target} (line ${line}). `
      + (andDeploy ? "Deploying it (see Deploy)…" : "Deploy when the checks are green.")));
    if (andDeploy) deploy();
  }

  return h("section", { class: "card rule-tool", "aria-label": "A new rule" },
    h("h3", {}, "A new rule"),
    h("div", { class: "field" }, h("label", { for: "new-rule-name" }, "Name of the rule (optional)"), nameEl),
    h("h4", {}, "When"), lists.when,
    sentenceMenu("Add a condition", "new-rule-when", sentenceGroups(conditions, use), (e) => pick("when", e)),
    noteEl,
    h("h4", {}, "Then"), lists.then,
    sentenceMenu("Add an action", "new-rule-then", sentenceGroups(actions, use), (e) => pick("then", e)),
    problemsEl,
    h("div", { class: "buttons" },
      deploy ? h("button", { class: "primary", onclick: () => add({ andDeploy: true }) }, "Add the rule and deploy") : null,
      h("button", { class: deploy ? "secondary" : "primary", onclick: () => add() }, "Add the rule"),
      h("button", { class: "secondary", onclick: (e) => {
        close();
        fill(e.target.closest(".rule-tool-panel"));
      } }, "Cancel")));
}
