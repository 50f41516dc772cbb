// The values a step's field can refer to, in the owner's words: what the run is given (the
// workflow's inputs, e.g. "the table (table1)") and what earlier steps found (a looked-up value, a
// variable a set step named). Why: without it the owner has to type `${input.table.id}`; with it
// they pick "the table (table1)" from a menu and the form writes the reference. No DOM here, so
// node's test runner checks it (web/test/workflow-values.test.mjs).

import { allSteps, samePath } from "./workflow-model.js";

const REFERENCE = /\$\{\s*([^}]*?)\s*\}/g;

/** "pepper_position" -> "the pepper position". */
function words(name) {
  return `the ${String(name).replace(/_/g, " ")}`;
}

/** A sample value as a short hint: "table1", "4.0", "2 items". */
function sample(value) {
  if (Array.isArray(value)) return `${value.length} ${value.length === 1 ? "item" : "items"}`;
  if (value && typeof value === "object") return value.id !== undefined ? String(value.id) : "";
  const text = String(value);
  return text.length > 24 ? `${text.slice(0, 23)}…` : text;
}

function choice(label, hint, ref, group) {
  return { label: hint ? `${label} (${hint})` : label, words: label, ref: `\${${ref}}`, expression: ref, group };
}

/** What the run is given: each input, and a thing's named parts ("the table's x"). */
function inputChoices(inputs) {
  const out = [];
  for (const [name, value] of Object.entries(inputs || {})) {
    const isThing = value && typeof value === "object" && !Array.isArray(value);
    if (isThing && value.id !== undefined) out.push(choice(words(name), sample(value), `input.${name}.id`, "given"));
    else out.push(choice(words(name), sample(value), `input.${name}`, "given"));
    if (!isThing) continue;
    for (const [part, partValue] of Object.entries(value)) {
      if (part === "id" || (partValue && typeof partValue === "object")) continue;
      out.push(choice(`${words(name)}'s ${part.replace(/_/g, " ")}`, sample(partValue), `input.${name}.${part}`, "given"));
    }
  }
  return out;
}

/** What the steps before `path` found: saved results and set steps' variables. */
function earlierChoices(doc, path) {
  const out = [];
  for (const { step, path: at } of allSteps(doc)) {
    if (samePath(at, path)) break;
    if (!step) continue;
    const module = step.module ? (doc.modules || {})[step.module] || {} : null;
    if (step.save) {
      const looked = module && module.kind === "ontology_value";
      const what = looked ? `the ${String((step.with || {}).name || (module.params || {}).name || step.save)} value`
        : `what step “${step.id}” gave`;
      out.push(choice(what, "", looked ? `${step.save}.value` : step.save, "found"));
    }
    for (const name of Object.keys(step.set || {})) out.push(choice(words(name), `set by step “${step.id}”`, name, "found"));
  }
  return out;
}

/** Every value the step at `path` may refer to: [{label, ref, expression, group}] ("given" first). */
export function valueChoices(doc, path) {
  if (!doc) return [];
  return [...inputChoices(doc.inputs), ...earlierChoices(doc, path)];
}

/** What one `${expression}` refers to: {choice} (one offered), {input} (an input the run is not
 *  given), {name} (a first name neither given nor found earlier), or {} (some other expression). */
function resolveReference(expression, choices) {
  const choice = choices.find((c) => c.expression === expression);
  if (choice) return { choice };
  const input = /^input\.([A-Za-z_]\w*)/.exec(expression);
  if (input) {
    const given = choices.some((c) => c.group === "given" && c.expression.split(".")[1] === input[1]);
    return given ? {} : { input: input[1] };
  }
  const first = expression.split(".")[0];
  const named = choices.some((c) => c.expression.split(".")[0] === first);
  return !named && /^[A-Za-z_][\w.]*$/.test(expression) ? { name: first } : {};
}

/** The references in a field's text in words: {known: ["the table (table1)"], unknown: ["tabel"]}.
 *  A reference is unknown when its first name is neither an input, nor a name found earlier. */
export function describeReferences(text, choices) {
  const known = [];
  const unknown = [];
  if (typeof text !== "string") return { known, unknown };
  for (const match of text.matchAll(REFERENCE)) {
    const { choice, input, name } = resolveReference(match[1], choices);
    if (choice) known.push(choice.label);
    else if (input || name) unknown.push(input || name);
  }
  return { known, unknown };
}

/** A step's summary line in words: each `${…}` it holds becomes what it stands for, in brackets
 *  ("say: Table [the table] is free"); an input the run is not given says so; any other
 *  expression is shown without its `${ }`. Why: the canvas is read by the owner, not the engine. */
export function referencesInWords(text, choices) {
  if (typeof text !== "string") return text;
  return text.replace(REFERENCE, (_, expression) => {
    const { choice, input } = resolveReference(expression, choices);
    if (choice) return `[${choice.words}]`;
    if (input) return `[${words(input)}: not given]`;
    return `[${expression}]`;
  });
}

/** `text` with `ref` put in at `at` (the cursor), or in place of the whole text when it is empty. */
export function insertReference(text, ref, at = null) {
  const current = text === undefined || text === null ? "" : String(text);
  if (!current.trim()) return ref;
  const where = at === null || at < 0 || at > current.length ? current.length : at;
  const before = current.slice(0, where);
  const gap = before && !/\s$/.test(before) ? " " : "";
  return `${before}${gap}${ref}${current.slice(where)}`;
}
