// Unit tests of the workflow document edits (run by tests/workbench/test_workbench_checks.py).
import { test } from "node:test";
import assert from "node:assert/strict";
import { removeProcess, renameProcess } from "../src/workflow-model.js";

const doc = () => ({
  processes: {
    greet: { steps: [{ id: "hello", module: "say" }, { id: "then_seat", process: "seat" }] },
    seat: { steps: [{ id: "check", if: "x", then: [{ id: "again", process: "seat" }], else: [] }] },
    last: { steps: [] },
  },
  services: { reception: { processes: ["greet", "seat"] }, other: { processes: ["last"] } },
});

test("a renamed process keeps its place and every reference follows", () => {
  const d = doc();
  assert.equal(renameProcess(d, "seat", "show_to_seat"), "");
  assert.deepEqual(Object.keys(d.processes), ["greet", "show_to_seat", "last"]);
  assert.deepEqual(d.services.reception.processes, ["greet", "show_to_seat"]);
  assert.equal(d.processes.greet.steps[1].process, "show_to_seat");
  assert.equal(d.processes.show_to_seat.steps[0].then[0].process, "show_to_seat");
});

test("a rename to a bad or taken name changes nothing and says why", () => {
  const d = doc();
  assert.match(renameProcess(d, "seat", "2nd"), /letters, digits and _/);
  assert.equal(renameProcess(d, "seat", "greet"), "There is already a process “greet”.");
  assert.deepEqual(d, doc());
  assert.equal(renameProcess(d, "seat", "seat"), "");
});

test("a removed process leaves the services that listed it; steps that run it stay for the checks", () => {
  const d = doc();
  assert.equal(removeProcess(d, "seat"), 1);
  assert.deepEqual(Object.keys(d.processes), ["greet", "last"]);
  assert.deepEqual(d.services.reception.processes, ["greet"]);
  assert.equal(d.processes.greet.steps[1].process, "seat");
});
