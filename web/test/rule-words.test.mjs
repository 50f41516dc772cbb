// Unit tests of the owner's rule tools' logic (web/src/rule-words.js): find and replace, and a new
// rule written from chosen sentences; run by tests/workbench/test_workbench_checks.py.
import { test } from "node:test";
import assert from "node:assert/strict";
import { fillSentence, findAll, holeProblem, isRuleText, newRuleProblems, ruleAt, ruleText, sentenceParts,
  sentenceShown } from "../src/rule-words.js";

test("findAll finds each exact place with its line", () => {
  const text = 'rule "A"\nthen\n    Pepper gestures "bow"\n    Pepper gestures "bow deeply"\n    Pepper gestures "bow"\n';
  assert.deepEqual(findAll(text, '"bow"').map((m) => m.line), [3, 5]);
  assert.deepEqual(findAll(text, "bow").map((m) => m.line), [3, 4, 5]);
  assert.deepEqual(findAll(text, ""), []);
  assert.deepEqual(findAll(text, "curtsey"), []);
});

test("ruleAt names the rule a line belongs to", () => {
  const rules = [{ name: "A", file: "r.dslr", line: 1 }, { name: "B", file: "r.dslr", line: 10 }, { name: "T", file: "t.xlsx", row: 3 }];
  assert.equal(ruleAt(rules, "r.dslr", 5).name, "A");
  assert.equal(ruleAt(rules, "r.dslr", 12).name, "B");
  assert.equal(ruleAt(rules, "other.drl", 12), null);
});

test("only rule texts are searched", () => {
  assert.ok(isRuleText("reception.dslr") && isRuleText("types.drl"));
  assert.ok(!isRuleText("reception.dsl") && !isRuleText("tests/reception.yaml") && !isRuleText("examples.json"));
});

test("sentences become parts, menu text and filled lines", () => {
  assert.equal(sentenceShown('Pepper says "{text}"'), 'Pepper says "…"');
  assert.equal(sentenceShown("- of exactly {n:\\d+} customers"), "- of exactly … customers");
  assert.deepEqual(sentenceParts('Pepper says "{text}"'), [{ text: 'Pepper says "' },
    { hole: { name: "text", regex: "", quoted: true } }, { text: '"' }]);
  assert.equal(fillSentence("- of exactly {n:\\d+} customers", { n: "2" }), "- of exactly 2 customers");
  assert.equal(fillSentence('Pepper says "{text}"', { text: "A blanket?" }), 'Pepper says "A blanket?"');
});

test("a hole's value is checked in words", () => {
  assert.equal(holeProblem({ name: "n", regex: "\\d+" }, "two"), "the n is a whole number, e.g. 2");
  assert.equal(holeProblem({ name: "text", regex: "", quoted: true }, 'say "hi"'), 'the text cannot contain a double quote (")');
  assert.equal(holeProblem({ name: "text", regex: "" }, " "), "fill in the text");
  assert.equal(holeProblem({ name: "n", regex: "\\d+" }, "2"), "");
});

test("a new rule is written as sentences, and refused with reasons", () => {
  assert.equal(ruleText("Offer blankets", ["There is a party at the entrance"], ['Pepper says "A blanket?"']),
    '\nrule "Offer blankets"\nwhen\n    There is a party at the entrance\nthen\n    Pepper says "A blanket?"\nend\n');
  assert.deepEqual(newRuleProblems("", [], [], []), ["Give the rule a name.", "Add at least one action under Then."]);
  assert.deepEqual(newRuleProblems("Infant", [], [{ shown: "x" }], ["Infant"]), ["There is already a rule named “Infant”."]);
  assert.deepEqual(newRuleProblems("New", [], [{ shown: 'Pepper says "…"', problem: "fill in the text" }], []),
    ['“Pepper says "…"”: fill in the text.']);
});

test("sentence menus are grouped: most used first, then the phrase book's sections, narrowing lines last", async () => {
  const { parseDsl } = await import("../src/checks.js");
  const { sentenceGroups, sentenceUse } = await import("../src/rule-words.js");
  const dsl = "# --- The party ---\n[condition][]There is a party=$e: Entrance()\n[condition][]- of {n:\\d+}=n == {n}\n"
    + "[condition][]Everyone has a type=not Customer(entrance == $e.id, category == null)\n"
    + "# --- Pepper ---\n[condition][]Pepper is here=$p: Robot()\n";
  const { entries } = parseDsl("x.dsl", dsl);
  const use = sentenceUse(entries, { "x.dslr": "rule a\nwhen\n There is a party\n Everyone has a type\nthen\nend\n"
    + "rule b\nwhen\n There is a party\n Everyone has a type\n Pepper is here\nthen\nend\n" });
  assert.deepEqual(sentenceGroups(entries, use).map((g) => [g.label, g.entries.map((e) => e.sentence)]), [
    ["Most used", ["There is a party", "Everyone has a type"]],
    ["The party", ["There is a party", "Everyone has a type"]],
    ["Pepper", ["Pepper is here"]],
    ["Narrowing the sentence above", ["- of {n:\\d+}"]],
  ]);
});

test("a sentence brings the one condition it is about; a name bound by several is left alone", async () => {
  const { parseDsl } = await import("../src/checks.js");
  const { neededConditions } = await import("../src/rule-words.js");
  const { entries } = parseDsl("x.dsl", "[condition][]There is a party=$e: Entrance()\n"
    + "[condition][]Everyone has a type=not Customer(entrance == $e.id)\n"
    + "[condition][]Pepper is here=$p: Robot(position == $e.id)\n[condition][]Pepper is away=$p: Robot()\n"
    + "[consequence][]Pepper comes=actions.move($e.getId()); modify($p) \\{ \\};\n");
  const [party, typed, , , comes] = entries;
  assert.deepEqual(neededConditions(typed, [], entries).map((e) => e.sentence), ["There is a party"]);
  assert.deepEqual(neededConditions(typed, [party], entries), []);
  assert.deepEqual(neededConditions(comes, [], entries).map((e) => e.sentence), ["There is a party"]);
});

test("a rule left unnamed is named after its first action, uniquely", async () => {
  const { defaultRuleName } = await import("../src/rule-words.js");
  assert.equal(defaultRuleName(['Pepper says "Hello"'], []), "Pepper says “Hello”");
  assert.equal(defaultRuleName(['Pepper says "Hello"'], ["Pepper says “Hello”"]), "Pepper says “Hello” (2)");
});
