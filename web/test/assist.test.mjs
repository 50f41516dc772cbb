// Unit tests of completion, hover and quick-fix logic (web/src/checks.js, web/src/assist-core.js);
// run by tests/workbench/test_workbench_checks.py.
import { test } from "node:test";
import assert from "node:assert/strict";
import { localProblems, nearestSentences, sectionAt, sentenceLabel, sentenceSnippet, CONSEQUENCE_SCOPES } from "../src/checks.js";
import { declaredTypes, dslEntries, explainLine, openPattern } from "../src/assist-core.js";

const DSL = `[condition][]There is a customer without a type=$c: Customer(category == null)
[condition][]- aged between {min:\\d+} and {max:\\d+}=age >= {min}, age <= {max}
[consequence][]Pepper says "{text}"=actions.say("pepper", "{text}");
[consequence][]The customer is a "{category}"=modify($c) \\{ setCategory("{category}") \\};
`;
const entries = dslEntries({ "r.dsl": DSL });
const RULE = `rule "Child"
when
    There is a customer without a type
    - aged between 4 and 12
then
    Pepper says "Hello"
end
`;

test("a sentence becomes a snippet whose holes are tab stops", () => {
  assert.equal(sentenceSnippet('Pepper says "{text}"'), 'Pepper says "${1:text}"');
  assert.equal(sentenceSnippet("- aged between {min:\\d+} and {max:\\d+}"), "- aged between ${1:min} and ${2:max}");
  assert.equal(sentenceSnippet("a \\{b\\} {c}", ["x"]), "a \\{b\\} ${1:x}");
  assert.equal(sentenceLabel("- aged between {min:\\d+} and {max:\\d+}"), "- aged between {min} and {max}");
});

test("the section of a line decides which sentences it may use", () => {
  const lines = RULE.split("\n");
  assert.equal(sectionAt(lines, 3), "when");
  assert.equal(sectionAt(lines, 6), "then");
  assert.equal(sectionAt(lines, 1), null);
});

test("hovering a line explains its DRL, with the line's values", () => {
  const lines = RULE.split("\n");
  assert.deepEqual(explainLine(lines, 4, entries).drl, "age >= 4, age <= 12");
  assert.equal(explainLine(lines, 4, entries).kind, "constraint");
  assert.equal(explainLine(lines, 4, entries).together, "$c: Customer(category == null, age >= 4, age <= 12)");
  assert.equal(explainLine(lines, 6, entries).drl, 'actions.say("pepper", "Hello");');
  assert.equal(explainLine(lines, 2, entries), null);
});

test("a misspelt sentence gets the nearest sentences as fixes, keeping its values", () => {
  const [fix] = nearestSentences('Pepper sayz "Hi there"', entries, CONSEQUENCE_SCOPES);
  assert.equal(fix.label, 'Pepper says "Hi there"');
  assert.equal(fix.template, 'Pepper says "${1:Hi there}"');
  const problems = localProblems({ "r.dsl": DSL, "r.dslr": RULE.replace("- aged between 4 and 12", "- aged from 4 to 12") });
  assert.equal(problems.length, 1);
  assert.equal(problems[0].fixes[0].label, "- aged between 4 and 12");
  assert.match(problems[0].message, /Did you mean “- aged between 4 and 12”/);
});

test("a clear typo gets one fix, not several guesses", () => {
  assert.deepEqual(nearestSentences('Pepper sayz "Hi"', entries, CONSEQUENCE_SCOPES).map((f) => f.label), ['Pepper says "Hi"']);
});

test("nothing is offered for a line far from every sentence", () => {
  assert.deepEqual(nearestSentences("Completely unrelated words here", entries, CONSEQUENCE_SCOPES), []);
});

test("DRL completion knows declared types and the pattern the cursor is in", () => {
  const types = declaredTypes({ "t.drl": "declare Customer\n    id : String\n    age : int // years\nend\n" }, { Robot: { id: "String" } });
  assert.deepEqual(types, { Robot: { id: "String" }, Customer: { id: "String", age: "int" } });
  assert.equal(openPattern("rule x\nwhen\n    $c: Customer(age > 3, "), "Customer");
  assert.equal(openPattern("    $c: Customer(age > 3)\n    Robot("), "Robot");
  assert.equal(openPattern("    $c: Customer(age > 3)\n    "), "");
});
