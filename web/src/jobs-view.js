// The rule author's view of build jobs: the progress of the deploy being built (a bar, the stage,
// done / total, "Cancel build") and the "Build jobs" card listing a rule set's recent jobs.

import { h, fill, when } from "./dom.js";
import { cancelJob, duration, firstError, isFinished, listJobs, progressFraction, progressText } from "./jobs.js";

/** The bar shows only when a build takes longer than this: a small rule set's job ends before, so
 * the deploy card goes straight from "Deploying…" to its result without a bar flashing by. */
export const SHOW_PROGRESS_AFTER_MS = 700;
/** How often the open list is refreshed while one of its jobs is unfinished. */
const LIST_REFRESH_MS = 1000;
const LIST_LIMIT = 10;

const STATUS_MARK = { queued: "○", running: "⟳", succeeded: "✓", failed: "✗", cancelled: "⊘" };

/** Set a `<progress>` to the job's fraction; indeterminate (no value) while it is unknown. */
function setBar(bar, job) {
  const fraction = progressFraction(job);
  if (fraction === null) bar.removeAttribute("value");
  else {
    bar.max = 1;
    bar.value = fraction;
  }
  return bar;
}

/** Why a cancel was refused, in words (409: it is past the point where it can be stopped, or over). */
function cancelRefused(err) {
  return err.status === 409 ? `Too late to cancel: ${err.message}` : `Not cancelled: ${err.message}`;
}

/** The progress of one build job in `host` (the deploy card's result area), with "Cancel build". */
export class JobProgress {
  constructor(host, job) {
    this.host = host;
    this.job = job;
    this.cancelRequested = false; // read by the deploy's end: a cancel that came too late is explained
    this.timer = setTimeout(() => this.show(), SHOW_PROGRESS_AFTER_MS);
  }

  update(job) {
    this.job = job;
    if (this.el) this.render();
  }

  show() {
    this.timer = null;
    if (isFinished(this.job)) return;
    this.textEl = h("span", { class: "job-progress-text", "data-testid": "deploy-stage" });
    this.elapsedEl = h("span", { class: "job-elapsed" });
    this.barEl = h("progress", { class: "job-bar", "aria-label": "Build progress" });
    this.noteEl = h("p", { class: "hint job-note", hidden: true, "data-testid": "cancel-note" });
    this.cancelEl = h("button", { class: "secondary", "data-testid": "cancel-build", onclick: () => this.cancel() }, "Cancel build");
    this.el = h("div", { class: "job-progress", "data-testid": "deploy-progress" },
      h("div", { class: "job-line" }, this.textEl, this.elapsedEl), this.barEl, this.noteEl, this.cancelEl);
    fill(this.host, this.el);
    this.render();
  }

  render() {
    this.el.dataset.status = this.job.status;
    this.textEl.textContent = progressText(this.job);
    this.elapsedEl.textContent = duration(this.job);
    setBar(this.barEl, this.job);
  }

  /** DELETE the job: a queued one ends at once, a running one ends at its next step; either way the
   * deploy's following sees the end. Only a refusal is told here. */
  async cancel() {
    this.cancelEl.disabled = true;
    this.cancelEl.textContent = "Cancelling…";
    this.cancelRequested = true;
    try {
      const answer = await cancelJob(this.job.id);
      if (answer && answer.cancel_requested && !isFinished(answer)) {
        this.note("Cancelling: the build stops at its next step. If it is already past compiling, it finishes and goes live.");
      }
    } catch (err) {
      this.cancelEl.hidden = true;
      this.note(cancelRefused(err));
    }
  }

  note(text) {
    this.noteEl.textContent = text;
    this.noteEl.hidden = false;
  }

  dispose() {
    clearTimeout(this.timer);
  }
}

/** What came of a job, in a line: the version it made, its first error, or where it is. */
function outcome(job) {
  if (job.status === "succeeded") {
    if (job.result && job.result.version) return `version ${job.result.version.version}`;
    if (job.result && "valid" in job.result) return job.result.valid ? "no problems" : `${job.result.errors.length} problem(s)`;
    return "done";
  }
  if (job.status === "failed") return firstError(job);
  if (job.status === "cancelled") return (job.error && job.error.error) || "cancelled";
  return progressText(job);
}

/** The "Build jobs" card: a rule set's latest jobs (kind, status, who, when, how long, the version
 * made or the first error), loaded when opened and refreshed while one of them is unfinished. */
export class JobsList {
  constructor({ ruleset, editable }) {
    this.ruleset = ruleset;
    this.editable = editable;
    this.seq = 0;
    this.timer = null;
    this.rows = new Map(); // job id -> {key, el, durationEl}: the rows shown
    this.listEl = h("ul", { class: "jobs-list", "data-testid": "jobs-list" });
    this.el = h("details", { class: "card jobs", "data-testid": "build-jobs", ontoggle: () => this.refresh() },
      h("summary", {}, "Build jobs"),
      h("p", { class: "hint" }, "Each deploy is built in the background on the gateway, one build at a time: here are the latest ones."),
      this.listEl);
  }

  /** Load the list again (only while the card is open: a closed card costs no requests). */
  async refresh() {
    clearTimeout(this.timer);
    if (this.disposed || !this.el.open) return;
    const seq = ++this.seq;
    let jobs;
    try {
      jobs = await listJobs(this.ruleset, LIST_LIMIT);
    } catch (err) {
      if (seq === this.seq) this.show(null, err.message);
      return;
    }
    if (seq !== this.seq) return;
    this.show(jobs);
    if (jobs.some((j) => !isFinished(j))) this.timer = setTimeout(() => this.refresh(), LIST_REFRESH_MS);
  }

  /** Draw the rows. A row whose job did not change is kept as it is (only its running time
   * moves), so nothing is rebuilt under the pointer by the refresh every second. */
  show(jobs, error = "") {
    if (error) {
      this.rows.clear();
      fill(this.listEl, h("li", { class: "message error", role: "alert" }, `Cannot list the build jobs: ${error}`));
      return;
    }
    if (!jobs.length) {
      this.rows.clear();
      fill(this.listEl, h("li", { class: "none muted" }, "No build jobs for this rule set yet."));
      return;
    }
    const rows = jobs.map((job) => this.rowFor(job));
    this.rows = new Map(jobs.map((job, i) => [job.id, rows[i]]));
    const els = rows.map((r) => r.el);
    const same = els.length === this.listEl.children.length && els.every((el, i) => this.listEl.children[i] === el);
    if (!same) fill(this.listEl, els);
  }

  /** The row of `job`: the one shown if the job is unchanged, else a new one. */
  rowFor(job) {
    const key = JSON.stringify(job);
    const known = this.rows.get(job.id);
    if (known && known.key === key) {
      known.durationEl.textContent = duration(job);
      return known;
    }
    const durationEl = h("span", { class: "job-duration" }, duration(job));
    return { key, durationEl, el: this.row(job, durationEl) };
  }

  row(job, durationEl) {
    const running = job.status === "running";
    return h("li", { class: `job ${job.status}`, "data-job-id": job.id, "data-status": job.status },
      h("div", { class: "job-line" },
        h("span", { class: `job-status ${job.status}` }, `${STATUS_MARK[job.status] || ""} ${job.status}`),
        h("span", { class: "job-kind" }, job.kind),
        h("span", { class: "job-outcome" }, outcome(job))),
      running ? setBar(h("progress", { class: "job-bar", "aria-label": "Build progress" }), job) : null,
      h("div", { class: "job-meta" }, `by ${job.author || "?"} · ${when(job.created_at)}`,
        job.started_at ? " · " : "", durationEl,
        job.cancel_requested && !isFinished(job) ? " · cancel requested" : ""),
      job.comment ? h("div", { class: "job-meta job-comment", title: job.comment }, job.comment) : null,
      this.editable && !isFinished(job) ? this.cancelButton(job) : null);
  }

  cancelButton(job) {
    const button = h("button", { class: "secondary small", "data-testid": "cancel-job", onclick: async () => {
      button.disabled = true;
      try {
        await cancelJob(job.id);
      } catch (err) {
        button.replaceWith(h("span", { class: "message error inline", role: "alert" }, cancelRefused(err)));
        return;
      }
      this.refresh();
    } }, "Cancel");
    return button;
  }

  dispose() {
    this.disposed = true; // the view is gone: no more requests (a deploy's end may still call refresh)
    clearTimeout(this.timer);
    this.seq++;
  }
}
