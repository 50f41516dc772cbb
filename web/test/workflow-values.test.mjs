// Unit tests of the values a step's field can refer to (run by tests/workbench/test_workbench_checks.py).
import { test } from "node:test";
import assert from "node:assert/strict";
import { describeReferences, insertReference, referencesInWords, valueChoices } from "../src/workflow-values.js";

const doc = () => ({
  inputs: { table: { id: "table1", x: 4.0, y: 2.0 }, customers: [{ id: "c1" }, { id: "c2" }], pepper_position: "entrance" },
  modules: { look: { kind: "ontology_value" }, say: { kind: "ros_service" } },
  processes: {
    p: { steps: [
      { id: "distance", module: "look", with: { name: "pepper1.robotToTableDistance" }, save: "table_distance" },
      { id: "names", set: { greeting: "hello" } },
      { id: "speak", module: "say" },
      { id: "later", set: { after: 1 } },
    ] },
  },
  services: { s: { processes: ["p"] } },
  route: { services: ["s"] },
});

test("a step is offered what the run is given and what the steps before it found, in words", () => {
  const choices = valueChoices(doc(), ["processes", "p", "steps", 2]);
  assert.deepEqual(choices.map((c) => [c.label, c.ref]), [
    ["the table (table1)", "${input.table.id}"],
    ["the table's x (4)", "${input.table.x}"],
    ["the table's y (2)", "${input.table.y}"],
    ["the customers (2 items)", "${input.customers}"],
    ["the pepper position (entrance)", "${input.pepper_position}"],
    ["the pepper1.robotToTableDistance value", "${table_distance.value}"],
    ["the greeting (set by step “names”)", "${greeting}"],
  ]);
  assert.ok(!choices.some((c) => c.ref === "${after}"), "a later step's variable is not offered");
});

test("references are told in words, and a name neither given nor found is named", () => {
  const choices = valueChoices(doc(), ["processes", "p", "steps", 2]);
  assert.deepEqual(describeReferences("Bill of ${input.table.id}", choices), { known: ["the table (table1)"], unknown: [] });
  assert.deepEqual(describeReferences("${input.tabel.id} and ${input.tables}", choices), { known: [], unknown: ["tabel", "tables"] });
  assert.deepEqual(describeReferences("${len(input.customers)}", choices), { known: [], unknown: [] });
  assert.deepEqual(describeReferences("${later_name}", choices), { known: [], unknown: ["later_name"] });
});

test("a step's summary tells its references in words", () => {
  const choices = valueChoices(doc(), ["processes", "p", "steps", 2]);
  assert.equal(referencesInWords("say: Bill of ${input.table.id} for ${ greeting }", choices), "say: Bill of [the table] for [the greeting]");
  assert.equal(referencesInWords("say: ${input.tabel.id}", choices), "say: [the tabel: not given]");
  assert.equal(referencesInWords("say: ${len(input.customers)} guests", choices), "say: [len(input.customers)] guests");
  assert.equal(referencesInWords("say: hello", choices), "say: hello");
});

test("a picked reference becomes the value of an empty field, else goes in at the cursor", () => {
  assert.equal(insertReference("", "${input.table.id}"), "${input.table.id}");
  assert.equal(insertReference(undefined, "${x}"), "${x}");
  assert.equal(insertReference("Settle the bill of", "${input.table.id}"), "Settle the bill of ${input.table.id}");
  assert.equal(insertReference("Go to  now", "${t}", 6), "Go to ${t} now");
});
