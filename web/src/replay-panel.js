// "What would change": the draft replayed over the rule set's recent decisions before Deploy
// (POST /api/rulesets/{name}/replay). Shows how often each rule would fire before and after, and
// the decisions that would change, before and after side by side, each linking to its decision.
// A deploy after a replay that changed decisions needs a comment, and the comment says so.

import { h, fill, when } from "./dom.js";
import { api, rulesetPath } from "./api.js";
import { actionList } from "./actions.js";

const RECENT = 1000;
const LISTED = 20;

export class WhatWouldChange {
  constructor(ctx, name, files) {
    this.ctx = ctx;
    this.name = name;
    this.files = files; // async () => the editor's files
    this.result = null;
    this.resultEl = h("div", { "data-testid": "replay-result", "aria-live": "polite" });
    this.button = h("button", { class: "big secondary", "data-testid": "replay", onclick: () => this.run() }, "What would change?");
    this.el = h("div", { class: "replay-panel" }, this.resultEl);
  }

  /** Replay the draft over the last RECENT decisions and show what it would change. */
  async run() {
    this.button.disabled = true;
    this.result = null;
    fill(this.resultEl, h("p", { class: "muted", role: "status" }, `Replaying the last ${RECENT} decisions on your text…`));
    try {
      const files = await this.files();
      this.result = await api("POST", `${rulesetPath(this.name)}/replay`, { files, limit: RECENT, max_changes: LISTED });
      fill(this.resultEl, this.render(this.result));
    } catch (err) {
      fill(this.resultEl, h("div", { class: "message error", role: "alert" },
        err.errors && err.errors.length ? "Your text does not build yet: fix the problems shown under the editor first." : `Cannot replay: ${err.message}`));
    } finally {
      this.button.disabled = false;
    }
  }

  /** Forget a replay once the text changed or was deployed (it no longer says what this text does). */
  reset() {
    this.result = null;
    fill(this.resultEl);
  }

  /** The comment a deploy gets: refused (null) when the replay changed decisions and no comment
   * says why; else the comment with the replay's count (kept in the version history). */
  comment(written) {
    const r = this.result;
    if (!r || !r.changed) return written;
    if (!written) return null;
    return `${written} [replay: ${r.changed} of ${r.replayed} recent decisions change]`;
  }

  render(r) {
    const summary = r.replayed
      ? `${r.changed} of ${r.replayed} recent decisions would change${r.failed ? `, ${r.failed} could not be replayed on your text` : ""}.`
      : r.note || "There are no recorded decisions to replay yet.";
    return h("div", { class: "card replay" },
      h("p", { class: r.changed ? "message warning" : "message ok", role: "status", "data-testid": "replay-summary" }, summary),
      r.not_replayable ? h("p", { class: "hint" }, `${r.not_replayable} decisions were made in a session or with too many facts to keep, and are not compared.`) : null,
      r.rules && r.rules.length ? h("table", { class: "replay-table", "data-testid": "replay-rules" },
        h("thead", {}, h("tr", {}, h("th", {}, "Rule"), h("th", {}, "fired before"), h("th", {}, "would fire"))),
        h("tbody", {}, r.rules.map((rule) => h("tr", { class: rule.before !== rule.after ? "changed" : "" },
          h("td", {}, rule.rule), h("td", {}, String(rule.before)), h("td", {}, String(rule.after)))))) : null,
      r.changes && r.changes.length ? h("div", { class: "replay-changes" },
        h("h3", {}, "Decisions that would change"),
        h("ol", {}, r.changes.map((c) => h("li", { "data-testid": "replay-change" },
          h("a", { href: this.ctx.href("decisions", c.decision_id) }, when(c.at)),
          h("div", { class: "side" },
            h("div", {}, h("b", {}, `Before (version ${c.before.version})`), h("p", {}, (c.before.fired || []).join(", ") || "no rule"), actionList(c.before.actions, "Nothing.")),
            h("div", {}, h("b", {}, "After your change"), h("p", {}, (c.after.fired || []).join(", ") || "no rule"), actionList(c.after.actions, "Nothing.")))))),
        r.changes_truncated ? h("p", { class: "hint" }, `and ${r.changed - r.changes.length} more.`) : null) : null);
  }
}
