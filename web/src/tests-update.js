// "Update the tests too": when a deploy is refused only because scenarios still expect a sentence
// or value the draft has changed (in an action or a fact) or name a rule it renamed, show each change (old → new) and offer to rewrite those
// expectations in the test files (POST /api/rulesets/{name}/tests/update; the gateway edits the
// YAML at its lines, comments kept, and stores nothing). Scenarios red for another reason are named
// and never rewritten. Self-contained: offerTestUpdate(host, options) -> Promise.

import { h, fill } from "./dom.js";
import { api, rulesetPath } from "./api.js";

function quoted(value) {
  return typeof value === "string" ? `“${value}”` : String(value);
}

/** What kind of thing changed, in the owner's words (a renamed rule, a value the rules set). */
const KIND = { rule: "rule renamed: ", fact: "value set by the rules: " };

/**
 * Ask the gateway which scenarios only expect changed words, and offer the update in `host`.
 * options: name, files (the draft), apply(updatedFiles, {allFixed}) (put the new test files into
 *          the editor; called when the button is pressed).
 */
export async function offerTestUpdate(host, { name, files, apply }) {
  fill(host, h("p", { class: "muted" }, "Looking whether the tests only expect the old words…"));
  let result;
  try {
    result = await api("POST", rulesetPath(name, "/tests/update"), { files });
  } catch {
    fill(host);
    return null;
  }
  const changes = result.changes || [];
  if (!changes.length) {
    fill(host);
    return result;
  }
  const kept = result.kept || [];
  const allFixed = !kept.length;
  const button = h("button", { class: "primary", "data-testid": "update-tests", onclick: () => {
    button.disabled = true;
    apply(result.files, { allFixed });
  } }, "Update the tests too");
  fill(host, h("div", { class: "tests-update", "data-testid": "tests-update" },
    h("p", {}, allFixed
      ? "These tests only expect the words you changed:"
      : "Some tests only expect the words you changed:"),
    h("ul", { class: "changes" }, changes.map((c) => h("li", {},
      h("b", {}, c.scenario), ` (${c.file}, line ${c.line}): ${KIND[c.what] || ""}`,
      h("del", {}, quoted(c.old)), " → ", h("ins", {}, quoted(c.new))))),
    kept.length ? h("p", { "data-testid": "tests-kept" }, `Still failing for another reason (not changed): ${kept.join(", ")}.`) : null,
    h("p", { class: "hint" }, allFixed
      ? "Update the tests too rewrites those expectations (nothing else in the test files changes) and deploys."
      : "Update the tests too rewrites those expectations; the others still need a look."),
    h("div", { class: "buttons" }, button)));
  return result;
}
