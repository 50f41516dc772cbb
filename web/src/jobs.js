// Build jobs (asynchronous deploys, see /api/jobs): submit one, follow it to its end, cancel it, and
// turn a failed job back into the ApiError the synchronous call would have thrown. Why that last
// part: the views keep one error handling (compile problems under the editor, red scenarios, 409
// conflicts) whether a deploy was answered at once or through a job.

import { api, ApiError, describe } from "./api.js";

/** How often a running job is asked for (its progress reaches the store about twice a second);
 * the first ask comes sooner, as a small rule set's build is over in a moment. */
export const POLL_MS = 400;
const FIRST_POLL_MS = 150;
/** Polls that may fail in a row (the gateway restarting, a network blip) before we give up following. */
const MAX_POLL_FAILURES = 5;
const FINISHED = new Set(["succeeded", "failed", "cancelled"]);

/** What each build stage is, in words (see gateway/engine/compiler.py, compile_files). */
const STAGES = {
  parse: "Reading the files",
  compile: "Compiling the rules",
  load: "Loading the compiled rules",
  assemble: "Putting the rule set together",
  scenarios: "Running the test scenarios",
};

export function jobPath(id) {
  return `/api/jobs/${encodeURIComponent(id)}`;
}

export function isFinished(job) {
  return FINISHED.has(job && job.status);
}

/** True for a job record (a 202 answer); false for a plain answer (a gateway that deployed at once). */
export function isJob(data) {
  return Boolean(data && typeof data.id === "string" && typeof data.status === "string" && "kind" in data);
}

/** Send a request as a build job (`Prefer: respond-async`): resolves with the queued job. */
export function submitJob(method, path, body) {
  return api(method, path, body, { Prefer: "respond-async" });
}

/** Ask the gateway to cancel a job: a queued one ends at once (the answer is the cancelled job), a
 * running one answers `cancel_requested` and ends later (cancelled, or succeeded if it was past
 * compiling); 409 when it can no longer be stopped. */
export function cancelJob(id) {
  return api("DELETE", jobPath(id));
}

/** The latest build jobs of a rule set, newest first. */
export async function listJobs(ruleset, limit = 10) {
  const data = await api("GET", `/api/jobs?ruleset=${encodeURIComponent(ruleset)}&limit=${limit}`);
  return (data && Array.isArray(data.jobs)) ? data.jobs : [];
}

/** Thrown by followJob when the caller stopped following (the view was closed); not a failure. */
export class FollowStopped extends Error {
  constructor() {
    super("stopped following the build job");
  }
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

/** Poll `job` until it ends; `onUpdate(job)` sees every state on the way, `stopped()` ends the
 * following early (FollowStopped). Resolves with the finished job. A few failed polls in a row are
 * tolerated; after that the ApiError carries `kind: "untracked"` (the build goes on without us). */
export async function followJob(job, { onUpdate = () => {}, stopped = () => false } = {}) {
  let failures = 0;
  let polls = 0;
  while (!isFinished(job)) {
    await sleep(polls++ ? POLL_MS : FIRST_POLL_MS);
    if (stopped()) throw new FollowStopped();
    try {
      job = await api("GET", jobPath(job.id));
      failures = 0;
    } catch (err) {
      if (err.status === 404 || ++failures >= MAX_POLL_FAILURES) {
        throw new ApiError(err.status, { kind: "untracked", error: err.message }, err.message);
      }
      continue;
    }
    if (stopped()) throw new FollowStopped();
    onUpdate(job);
  }
  return job;
}

/** A failed or cancelled job's `error` (the synchronous call's body plus the `status` it would have
 * answered) as the ApiError api() would have thrown for that call. */
export function jobError(job) {
  const { status, ...body } = (job && job.error) || { error: `the build job ended ${job && job.status}` };
  const code = Number(status) || (job && job.status === "cancelled" ? 409 : 500);
  return new ApiError(code, body, describe(code, body));
}

/** A cancelled job's error, told apart from a 409 version conflict (both answer 409). */
export function isCancelled(err) {
  return Boolean(err && err.body && err.body.kind === "cancelled");
}

/** What the synchronous deploy answered (`{name, version}`) for a finished deploy job, or the
 * ApiError it would have thrown. A plain answer (a gateway without jobs) is returned as it is. */
export function deployOutcome(job) {
  if (!isJob(job)) return job;
  if (job.status !== "succeeded") throw jobError(job);
  const info = (job.result && job.result.version) || {};
  return { name: info.name || job.ruleset, version: info.version };
}

/** Where a job is, in words: "Waiting for another build…", "Compiling the rules: 412 / 1000". */
export function progressText(job) {
  if (job.status === "queued") return "Waiting for another build to finish first…";
  const p = job.progress;
  if (!p || !p.stage) return "Starting the build…";
  const stage = STAGES[p.stage] || p.stage;
  return p.total > 1 ? `${stage}: ${p.done} / ${p.total}` : `${stage}…`;
}

/** The job's progress as a fraction in [0, 1], or null when unknown (queued, just started). */
export function progressFraction(job) {
  const p = job.progress;
  if (job.status !== "running" || !p || !(p.total > 0)) return null;
  return Math.max(0, Math.min(1, p.done / p.total));
}

/** The first thing that went wrong in a failed job, in a line: "x.dslr, line 3: mismatched input…". */
export function firstError(job) {
  const error = job.error || {};
  if (error.kind === "scenarios" || error.kind === "conflict") return error.detail || error.error;
  const first = Array.isArray(error.errors) && error.errors[0];
  if (first && (first.message || first.msg)) {
    const where = first.cell ? `${first.file}, cell ${first.sheet ? `${first.sheet}!` : ""}${first.cell}`
      : first.file ? `${first.file}${first.line ? `, line ${first.line}` : ""}` : "";
    return `${where ? `${where}: ` : ""}${first.message || first.msg}`;
  }
  return error.detail || error.error || "failed";
}

/** How long a job took (or has been running, with `now`), e.g. "2.4 s", "1 min 5 s"; "" when not started. */
export function duration(job, now = Date.now()) {
  if (!job.started_at) return "";
  const start = Date.parse(job.started_at);
  const end = job.finished_at ? Date.parse(job.finished_at) : now;
  if (Number.isNaN(start) || Number.isNaN(end)) return "";
  const seconds = Math.max(0, (end - start) / 1000);
  if (seconds < 10) return `${seconds.toFixed(1)} s`;
  if (seconds < 60) return `${Math.round(seconds)} s`;
  return `${Math.floor(seconds / 60)} min ${Math.round(seconds % 60)} s`;
}
