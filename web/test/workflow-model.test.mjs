// Unit tests of the workflow document edits (run by tests/workbench/test_workbench_checks.py).
import { test } from "node:test";
import assert from "node:assert/strict";
import {
  newVariableName, removeProcess, renameProcess, renameVariable, variableText, variableValue,
} from "../src/workflow-model.js";

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

test("set step values: numbers, true/false and null typed, everything else text", () => {
  assert.equal(variableValue("2"), 2);
  assert.equal(variableValue("-1.5"), -1.5);
  assert.equal(variableValue("true"), true);
  assert.equal(variableValue("null"), null);
  assert.equal(variableValue("${len(input.orders)}"), "${len(input.orders)}");
  assert.equal(variableValue("Thank you"), "Thank you");
  for (const v of [2, true, null, "text"]) assert.equal(variableValue(variableText(v)), v);
});

test("a set step's variable is renamed in place, never onto another", () => {
  const step = { id: "s", set: { a: 1, b: 2 } };
  assert.equal(renameVariable(step, "a", "b"), "The step already sets “b”.");
  assert.equal(renameVariable(step, "a", "1x").length > 0, true);
  assert.equal(renameVariable(step, "a", "c"), "");
  assert.deepEqual(Object.entries(step.set), [["c", 1], ["b", 2]]);
  assert.equal(newVariableName({ set: { value: 1 } }), "value_2");
});
