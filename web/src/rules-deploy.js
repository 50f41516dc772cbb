// The Rules view's Deploy card: the comment, the build job and its progress, and why nothing was
// deployed (problems, conflicts, a cancelled build). Mixed into RulesView (rules-view.js).

import { rulesetPath } from "./api.js";
import { h, fill } from "./dom.js";
import { JobProgress, JobsList } from "./jobs-view.js";
import { FollowStopped, deployOutcome, followJob, isCancelled, isJob, submitJob } from "./jobs.js";
import { WhatWouldChange } from "./replay-panel.js";
import { normalizeErrors, draftKey } from "./rules-common.js";

export const deployMethods = {
  // ---- Deploy ---------------------------------------------------------------------------------

  buildDeploy() {
    if (!this.editable) return null;
    this.commentEl = h("input", { type: "text", class: "comment", maxlength: "500", "aria-label": "What did you change?",
      placeholder: "e.g. Friendlier greeting for groups" });
    this.deployResultEl = h("div", { class: "deploy-result", "data-testid": "deploy-result", "aria-live": "polite" });
    this.deployButton = h("button", { class: "big primary", "data-testid": "deploy", onclick: () => this.deploy() }, "Deploy to the robot");
    this.replay = new WhatWouldChange(this.ctx, this.name, async () => {
      await this.flushTables();
      return this.files();
    });
    return h("div", { class: "card deploy" },
      h("h2", {}, "Deploy"),
      h("label", { class: "field" }, "What did you change? (shown in the history)", this.commentEl),
      h("div", { class: "buttons" },
        this.replay.button,
        this.deployButton,
        h("button", { class: "big secondary", onclick: () => this.discard() }, "Undo all my changes")),
      this.replay.el,
      this.deployResultEl);
  },

  /** The rule set's recent build jobs (collapsed until wanted). */
  buildJobs() {
    this.jobsList = new JobsList({ ruleset: this.name, editable: this.editable });
    return this.jobsList.el;
  },

  // ---- Deploy ---------------------------------------------------------------------------------

  async deploy(force = false) {
    if (this.building) return; // one build at a time from this page (the button is disabled meanwhile)
    this.setBuilding(true);
    fill(this.deployResultEl, h("p", { class: "muted" }, "Deploying…"));
    try {
      await this.flushTables();
      const files = this.files();
      const comment = this.replay ? this.replay.comment(this.commentEl.value.trim()) : this.commentEl.value.trim();
      if (comment === null) {
        fill(this.deployResultEl, h("div", { class: "message error", role: "alert", "data-testid": "replay-comment-needed" },
          `Your change would change ${this.replay.result.changed} recent decisions: say what you changed and why in the comment, then deploy.`));
        this.commentEl.focus();
        return;
      }
      const body = { files, comment, base_version: this.base };
      if (force) body.force = true;
      this.deployed(files, comment, await this.buildAndDeploy(body));
    } catch (err) {
      this.notDeployed(err);
    } finally {
      this.setBuilding(false);
    }
  },

  /** While a build runs the Deploy button rests, and the result area is busy (screen readers then
   * announce its end, not every step of the progress). */
  setBuilding(on) {
    this.building = on;
    this.deployButton.disabled = on;
    if (on) this.deployResultEl.setAttribute("aria-busy", "true");
    else this.deployResultEl.removeAttribute("aria-busy");
  },

  /** Deploy `body` through a build job: its progress shows while it builds (after a moment, so a
   * quick one flashes no bar) and its end becomes what the synchronous deploy answered or threw. */
  async buildAndDeploy(body) {
    this.progress = null;
    const job = await submitJob("PUT", rulesetPath(this.name), body);
    if (!isJob(job)) return job; // a gateway that deployed at once
    const progress = new JobProgress(this.deployResultEl, job);
    this.progress = progress;
    this.jobsList.refresh();
    try {
      const done = await followJob(job, { onUpdate: (j) => progress.update(j), stopped: () => this.disposed });
      return deployOutcome(done);
    } finally {
      progress.dispose();
      this.jobsList.refresh();
    }
  },

  /** The new version is live: the editor's text is now the deployed one. */
  deployed(files, comment, result) {
    this.original = files;
    this.base = result.version;
    this.info = { ...this.info, version: result.version, author: this.ctx.user?.name, comment, deployed_at: new Date().toISOString() };
    localStorage.removeItem(draftKey(this.name));
    this.commentEl.value = "";
    this.replay?.reset();
    this.renderLive();
    this.updateDirty();
    fill(this.deployResultEl, h("div", { class: "message ok", role: "status" }, `✓ Deployed. Version ${result.version} is now live.`),
      this.progress?.cancelRequested ? h("p", { class: "hint" }, "The build was too far along to cancel, so it finished.") : null);
    this.ctx.refreshRulesets();
  },

  /** Say why nothing was deployed: compile problems go under the editor, red scenarios and
   * conflicts get their own choices, a cancelled build keeps the edits. */
  notDeployed(err) {
    if (err instanceof FollowStopped) return; // the view was closed while the build ran
    if (isCancelled(err)) this.buildCancelled(err);
    else if (err.body && err.body.kind === "untracked") this.lostTrack(err);
    else if (err.status === 409) this.conflict(err.body && err.body.current);
    else if (err.body && err.body.kind === "scenarios") this.redScenarios(err.body);
    else if (err.errors && err.errors.length) {
      this.server = normalizeErrors(err.errors);
      this.renderProblems(false);
      fill(this.deployResultEl, h("div", { class: "message error", role: "alert" }, err.body && err.body.kind === "policy"
        ? `Not deployed: the rule policy refuses ${this.server.length} place(s) for your role (listed under the editor): `
          + "an author's rules may use the rule set's own types, its actions and insert/modify/update/delete, not other "
          + "Java. A developer may deploy such rules. Nothing was changed."
        : `Not deployed: fix the ${this.server.length} problem(s) listed under the editor first. Nothing was changed.`));
    } else fill(this.deployResultEl, h("div", { class: "message error", role: "alert" }, `Not deployed: ${err.message}`));
  },

  buildCancelled(err) {
    const why = /^cancelled\b/.test(err.message) ? err.message : `cancelled (${err.message})`; // "cancelled by alice"
    fill(this.deployResultEl, h("div", { class: "message info", role: "status", "data-testid": "build-cancelled" },
      `Not deployed: the build was ${why}. Nothing was changed; your changes are still here.`));
  },

  /** Following the job failed (the gateway stopped answering): the build may still end either way. */
  lostTrack(err) {
    fill(this.deployResultEl, h("div", { class: "message warning", role: "alert" },
      `Lost track of the build (${err.message}). It may still finish: see Build jobs, or reload the page in a moment.`));
  },

  conflict(current) {
    const started = this.base;
    const compare = `#/history/${encodeURIComponent(this.name)}?from=${started}&to=${current}`;
    fill(this.deployResultEl, h("div", { class: "message warning", role: "alert", "data-testid": "conflict" },
      h("p", {}, `Not deployed: someone else deployed version ${current} while you were editing (you started from version ${started}). `,
        "Your changes are still here; nothing was lost."),
      h("div", { class: "buttons" },
        h("a", { class: "button secondary", href: compare, target: "_blank", rel: "noopener" }, `See what changed in version ${current}`),
        h("button", { class: "secondary", onclick: () => {
          this.base = current;
          this.storeDraft();
          this.deploy();
        } }, `Deploy mine anyway (replaces version ${current}; it stays in the history)`))));
  },
};
