// Unit tests of the owner's-first-hour helpers (run by tests/workbench/test_workbench_checks.py):
// knowledge values in words, the palette without duplicates, field labels.
import { test } from "node:test";
import assert from "node:assert/strict";
import { expectation, kindWords, typeProblem } from "../src/value-words.js";
import { paletteRows } from "../src/palette-entries.js";
import { fieldLabel } from "../src/field-label.js";
import { moduleFor } from "../src/workflow-model.js";

const metres = { unit: "metres", limits: { minInclusive: "0", maxInclusive: "20" } };

test("a value's expectation in words, with unit, limits and an example", () => {
  assert.equal(expectation("decimal", { ...metres, example: "3.3" }), "a number in metres from 0 to 20, e.g. 3.3");
  assert.equal(expectation("decimal", { unit: "seconds", limits: { minInclusive: "1500" } }), "a number in seconds, at least 1500, e.g. 1500");
  assert.equal(expectation("integer"), "a whole number, e.g. 3");
  assert.equal(kindWords("decimal", metres), "number in metres, 0 to 20");
});

test("type and limit problems say what is expected, as the gateway does", () => {
  const spec = { ...metres, example: "3.3" };
  assert.equal(typeProblem("distanceToEntrance", "decimal", "far away", spec),
    "distanceToEntrance: 'far away' is not a number in metres from 0 to 20, e.g. 3.3");
  assert.equal(typeProblem("distanceToEntrance", "decimal", "-1", spec),
    "distanceToEntrance: -1 metres is below the least allowed, 0 metres; give a number in metres from 0 to 20, e.g. 3.3");
  assert.match(typeProblem("distanceToEntrance", "decimal", "21", spec), /21 metres is above the most allowed, 20 metres/);
  assert.equal(typeProblem("distanceToEntrance", "decimal", "2.5", spec), "");
  assert.equal(typeProblem("distanceToEntrance", "decimal", " ", spec), "distanceToEntrance: a value is needed");
});

test("a module and the palette entry it was made from are one row, named by the entry", () => {
  const say = { id: "pepper.speak", group: "Robot services", kind: "ros_service", label: "Pepper: say",
    module: { kind: "ros_service", service: "/pepper/speak" } };
  const hsr = { id: "hsr.move_to", group: "Robot services", kind: "ros_service", label: "Hsr: move to",
    module: { kind: "ros_service", service: "/hsr/move_to" } };
  const rules = { id: "fire_rules", group: "Business rules", kind: "fire_rules", label: "Fire business rules", module: { kind: "fire_rules" } };
  const doc = { modules: { say: { kind: "ros_service", service: "/pepper/speak" }, fire_reception_rules: { kind: "fire_rules", ruleset: "reception" } } };
  const { mine, groups } = paletteRows(doc, [say, hsr, rules], moduleFor);
  assert.deepEqual(mine.map((r) => [r.name, r.label]), [["say", "Pepper: say"], ["fire_reception_rules", "Fire the reception rules"]]);
  assert.deepEqual(Object.fromEntries(Object.entries(groups).map(([g, es]) => [g, es.map((e) => e.label)])),
    { "Robot services": ["Hsr: move to"], "Business rules": ["Fire business rules"] });
});

test("a field is named as its form labels it", () => {
  assert.equal(fieldLabel("with.text"), "text");
  assert.equal(fieldLabel("set.greeting"), "variable greeting");
  assert.equal(fieldLabel("params.robot"), "robot");
  assert.equal(fieldLabel("id"), "id");
  assert.equal(fieldLabel(""), "");
});
