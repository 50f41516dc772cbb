// Unit tests of the build-job helpers (run by tests/workbench/test_workbench_checks.py): a finished
// job must turn into exactly what the synchronous deploy answered or threw.
import { test } from "node:test";
import assert from "node:assert/strict";
import { deployOutcome, duration, firstError, isCancelled, isJob, jobError, progressFraction, progressText } from "../src/jobs.js";

const job = (fields) => ({ id: "j1", kind: "deploy", ruleset: "reception", status: "running", progress: null, ...fields });

test("a succeeded deploy job answers {name, version} like the synchronous deploy", () => {
  const done = job({ status: "succeeded", result: { version: { name: "reception", version: 7, author: "alice" } } });
  assert.deepEqual(deployOutcome(done), { name: "reception", version: 7 });
});

test("a plain answer (a gateway that deployed at once) passes through", () => {
  assert.equal(isJob({ name: "reception", version: 3 }), false);
  assert.deepEqual(deployOutcome({ name: "reception", version: 3 }), { name: "reception", version: 3 });
});

test("a failed job throws the synchronous call's error: compile problems with file and line", () => {
  const errors = [{ file: "reception.dslr", line: 12, column: 14, message: "mismatched input ')'" }];
  const failed = job({ status: "failed", error: { kind: "compile", error: "rule set does not compile", errors, status: 422 } });
  assert.throws(() => deployOutcome(failed), (err) => {
    assert.equal(err.status, 422);
    assert.deepEqual(err.errors, errors);
    assert.equal(err.body.status, undefined); // the status is the error's, not part of the body
    assert.equal(err.message, "rule set does not compile");
    return true;
  });
});

test("a conflict keeps its 409 and the current version; a cancel is told apart from it", () => {
  const conflict = jobError(job({ status: "failed", error: { kind: "conflict", error: "base version changed", current: 4, status: 409 } }));
  assert.equal(conflict.status, 409);
  assert.equal(conflict.body.current, 4);
  assert.equal(isCancelled(conflict), false);
  const cancelled = jobError(job({ status: "cancelled", error: { kind: "cancelled", error: "cancelled by alice", status: 409 } }));
  assert.equal(isCancelled(cancelled), true);
  assert.equal(cancelled.message, "cancelled by alice");
});

test("a failed job without a status still becomes an error", () => {
  const err = jobError(job({ status: "failed", error: { kind: "internal", error: "RuntimeError: boom" } }));
  assert.equal(err.status, 500);
  assert.equal(err.message, "RuntimeError: boom");
});

test("progress in words and as a fraction", () => {
  assert.match(progressText(job({ status: "queued" })), /Waiting/);
  assert.equal(progressFraction(job({ status: "queued" })), null);
  assert.match(progressText(job({})), /Starting/);
  const compiling = job({ progress: { stage: "compile", done: 412, total: 1000 } });
  assert.equal(progressText(compiling), "Compiling the rules: 412 / 1000");
  assert.equal(progressFraction(compiling), 0.412);
  assert.equal(progressText(job({ progress: { stage: "assemble", done: 0, total: 1 } })), "Putting the rule set together…");
});

test("the first error of a failed job, and how long a job took", () => {
  const failed = job({ status: "failed", error: { kind: "compile", errors: [{ file: "a.dslr", line: 3, column: 5, message: "bad" }] } });
  assert.equal(firstError(failed), "a.dslr, line 3: bad");
  assert.equal(firstError(job({ status: "failed", error: { kind: "conflict", error: "base version changed", detail: "at version 4" } })), "at version 4");
  assert.equal(duration(job({ started_at: "2024-01-01T00:00:00Z", finished_at: "2024-01-01T00:00:02.4Z" })), "2.4 s");
  assert.equal(duration(job({ started_at: "2024-01-01T00:00:00Z", finished_at: "2024-01-01T00:01:05Z" })), "1 min 5 s");
  assert.equal(duration(job({ started_at: null })), "");
});
