// The workflow editor's run panel: run the live version or try the unsaved edits on the simulated
// robots and follow the trace step by step. Mixed into WorkflowEditor (workflow-view.js).

import { api } from "./api.js";
import { h, fill } from "./dom.js";
import { wfPath } from "./workflow-versions.js";

const TRACE_STEP_MS = 300; // one trace entry at a time, so the eye can follow the run
const RUN_POLL_MS = 250;

export const runMethods = {
  // ------------------------------------------------------------------ running

  renderRun() {
    const inputsEl = h("textarea", { id: "wf-inputs", rows: 3, "aria-label": "Run inputs (JSON; empty: the workflow's defaults)",
      placeholder: "{} — the workflow's default inputs" });
    this.traceEl = h("ol", { class: "wf-trace", "data-testid": "wf-trace", "aria-live": "polite", "aria-label": "Run trace" });
    this.runMsgEl = h("div", { "aria-live": "polite" });
    fill(this.runEl, h("h2", {}, "Run on the simulated robots"),
      h("p", { class: "hint" }, "Runs the saved (live) version; the trace shows each step as it happens."),
      h("details", {}, h("summary", {}, "Inputs"), h("label", { for: "wf-inputs", class: "hint" }, "JSON object, e.g. {\"orders\": []}"), inputsEl),
      h("div", { class: "buttons" },
        h("button", { class: "primary", "data-testid": "wf-run", onclick: () => this.run(inputsEl.value) }, "Run the live version"),
        this.ctx.isAuthor() ? h("button", { class: "secondary", "data-testid": "wf-try", onclick: () => this.run(inputsEl.value, true) },
          "Try my unsaved edits") : null),
      this.runMsgEl, this.traceEl);
  },

  /** Run the live version, or (`trial`) the edited text without saving it; follow it step by step. */
  async run(inputsText, trial = false) {
    let inputs = {};
    if (inputsText.trim()) {
      try {
        inputs = JSON.parse(inputsText);
        if (!inputs || typeof inputs !== "object" || Array.isArray(inputs)) throw new Error("not an object");
      } catch (err) {
        fill(this.runMsgEl, h("div", { class: "message error", role: "alert" }, `Inputs: not a JSON object (${err.message}).`));
        return;
      }
    }
    this.timers.forEach(clearTimeout);
    this.timers = [];
    clearInterval(this.revealTimer);
    this.trace = [];
    this.markTrace();
    fill(this.traceEl);
    fill(this.runMsgEl, h("p", { class: "muted", role: "status" }, this.dirty
      ? (trial ? "Trying your unsaved edits (nothing is saved or made live)…" : `Running the saved version ${this.version} (your unsaved changes are not run)…`)
      : `Running version ${this.version}…`));
    let started;
    try {
      if (trial) await this.flush();
      started = trial ? await api("POST", "/api/workflows/try", { text: this.text, inputs })
        : await api("POST", wfPath(this.name, "/run"), { inputs, wait: false });
    } catch (err) {
      const why = err.status === 422 ? "your edits have problems (listed above); fix them, then try again." : err.message;
      fill(this.runMsgEl, h("div", { class: "message error", role: "alert" }, `The run could not start: ${why}`));
      return;
    }
    // The steps arrive as the robots do them (polling the run); they are shown one at a time.
    const runId = started.run_id;
    this.runId = runId;
    const queue = [];
    let received = 0;
    let final = null;
    const poll = async () => {
      if (this.disposed || this.runId !== runId) return;
      let data;
      try {
        data = await api("GET", `/api/workflows/runs/${encodeURIComponent(runId)}`);
      } catch (err) {
        final = { status: "failed", error: `the run could not be followed: ${err.message}`, steps: [] };
        return;
      }
      const steps = data.steps || [];
      queue.push(...steps.slice(received));
      received = Math.max(received, steps.length);
      if (data.status === "running") this.timers.push(setTimeout(poll, RUN_POLL_MS));
      else final = data;
    };
    let shown = 0;
    this.revealTimer = setInterval(() => {
      if (this.disposed || this.runId !== runId) return clearInterval(this.revealTimer);
      if (queue.length) {
        this.showRecord(queue.shift(), shown);
        shown += 1;
      } else if (final) {
        clearInterval(this.revealTimer);
        this.markTrace();
        fill(this.runMsgEl, h("div", { class: `message ${final.status === "succeeded" ? "ok" : "error"}`, role: "status", "data-testid": "wf-run-status" },
          final.status === "succeeded" ? `Run ${runId} of ${trial ? "your unsaved edits" : `version ${final.version}`} succeeded: ${shown} steps.`
            : `Run ${runId} failed: ${final.error}`));
      }
    }, TRACE_STEP_MS);
    poll();
  },

  showRecord(record, index) {
    if (this.disposed) return;
    const p = record.params || {};
    const looked = record.kind === "ontology_value" && record.output && record.output.value !== undefined;
    const what = looked ? `${p.name} = ${record.output.value}`
      : p.text ?? p.name ?? p.location ?? p.prompt ?? (p.seconds !== undefined ? `${p.seconds} s` : "");
    const coords = p.x !== undefined ? `(${p.x}, ${p.y})` : "";
    this.traceEl.append(h("li", { class: `wf-record ${record.status}`, "data-step": record.step_id, "data-index": index },
      h("span", { class: "mark" }, record.status === "ok" ? "✓" : record.status === "skipped" ? "–" : "✗"),
      h("b", {}, record.step_id), ` · ${record.module || record.type}${record.via ? ` (via ${record.via})` : ""}`,
      record.actor ? h("span", { class: "muted" }, ` · ${record.actor}`) : null,
      what || coords ? h("span", { class: "wf-said" }, `: ${what || coords}`) : null,
      record.error ? h("span", { class: "wf-error" }, ` — ${record.error}`) : null));
    this.trace = (this.trace || []).concat([record]);
    this.markTrace(record.step_id);
  },

  /** Highlight the steps of the process view the run went through (and the current one). */
  markTrace(current = null) {
    const done = new Set((this.trace || []).map((r) => r.step_id));
    for (const li of this.panelEl.querySelectorAll("li.wf-step")) {
      li.classList.toggle("ran", done.has(li.dataset.step));
      li.classList.toggle("running", !!current && li.dataset.step === current);
    }
  },
};
