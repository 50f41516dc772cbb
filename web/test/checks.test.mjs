// Unit tests of the browser-side checks (run by tests/workbench/test_workbench_checks.py).
import { test } from "node:test";
import assert from "node:assert/strict";
import { localProblems, parseDsl, sentencePattern } from "../src/checks.js";

const DSL = `# comment
[condition][]There is a customer aged {age:\\d+}=c: Customer(age == {age})
[condition][]- who is {gender}=gender == "{gender}"
[consequence][]Pepper says "{text}"=actions.say("pepper", "{text}");
`;
const rule = (when, then) => `rule "r"\nwhen\n    ${when}\nthen\n    ${then}\nend\n`;

test("sentences matching the phrase book pass", () => {
  const files = { "a.dsl": DSL, "a.dslr": rule("There is a customer aged 30\n    - who is female", 'Pepper says "Hi"') };
  assert.deepEqual(localProblems(files), []);
});

test("an unknown sentence is marked where it stands", () => {
  const problems = localProblems({ "a.dsl": DSL, "a.dslr": rule("There is a customer aged thirty", 'Pepper says "Hi"') });
  assert.equal(problems.length, 1);
  assert.deepEqual([problems[0].file, problems[0].line, problems[0].column, problems[0].severity], ["a.dslr", 3, 5, "warning"]);
});

test("raw DRL lines (>) and comments are not sentences", () => {
  const files = { "a.dsl": DSL, "a.dslr": rule(">$c: Customer()\n    // note", 'Pepper says "Hi"') };
  assert.deepEqual(localProblems(files), []);
});

test("a .dsl line that is no entry is an error at its line", () => {
  const { entries, problems } = parseDsl("x.dsl", "[when]ok=1\nthis is not an entry\n");
  assert.equal(entries.length, 1);
  assert.deepEqual([problems[0].line, problems[0].severity], [2, "error"]);
});

test("escaped characters and typed holes", () => {
  assert.ok(sentencePattern("a \\{b\\} {n:\\d+}").test("a {b} 12"));
  assert.ok(!sentencePattern("a {n:\\d+}").test("a twelve"));
});

test("control characters from pasted binary data are errors", () => {
  const [problem] = localProblems({ "a.drl": "rule\n  x\u0000y\n" });
  assert.deepEqual([problem.line, problem.column, problem.severity], [2, 4, "error"]);
  assert.match(problem.message, /U\+0000/);
});
