// The workflow editor's versions tab (compare, roll back) and saving (conflicts, discarding edits).
// Mixed into WorkflowEditor (workflow-view.js).

import { MergeView } from "@codemirror/merge";
import { EditorState } from "@codemirror/state";
import { EditorView } from "@codemirror/view";
import { basicSetup } from "codemirror";
import { api } from "./api.js";
import { h, fill, when } from "./dom.js";
import { languageFor } from "./lang.js";

/** The REST path of workflow `name` (and of `rest` under it). */
export const wfPath = (name, rest = "") => `/api/workflows/${encodeURIComponent(name)}${rest}`;

export const versionMethods = {
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
  },

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
  },

  async rollback(version) {
    if (this.dirty && !window.confirm("Rolling back discards your unsaved changes. Go on?")) return;
    try {
      const result = await api("POST", wfPath(this.name, "/rollback"), { version, comment: `rollback to version ${version}` });
      this.ctx.flash("ok", `Rolled back: version ${result.version} is live again.`);
      this.ctx.navigate(this.ctx.href("workflows", this.name, "tab=versions"), true);
    } catch (err) {
      fill(this.saveMsgEl, h("div", { class: "message error", role: "alert" }, `Not rolled back: ${err.message}`));
    }
  },

  // ------------------------------------------------------------------ saving

  async flush() {
    this.checkSoon.cancel();
    if (this.yamlCheck) this.yamlCheck.cancel();
    await this.check(this.tab === "yaml" && this.yamlView ? { text: this.yamlView.state.doc.toString() } : undefined);
  },

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
  },

  conflict(current) {
    fill(this.saveMsgEl, h("div", { class: "message error", role: "alert", "data-testid": "wf-conflict" },
      h("p", {}, `Not saved: someone else saved version ${current} of this workflow while you were editing version ${this.base}. `
        + "Nothing changed live, and your edits are still here."),
      h("div", { class: "buttons" },
        h("button", { class: "secondary", onclick: (e) => this.compareWithLive(current, e.currentTarget) }, `Compare my edits with version ${current}`),
        h("button", { class: "danger", onclick: () => { this.version = current; this.base = current; this.save(current); } }, `Save mine over version ${current}`))));
  },

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
  },

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
  },
};
