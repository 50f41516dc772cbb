// A knowledge value in an owner's words: what it must be ("a number in metres from 0 to 5, e.g.
// 1.0"), its unit and limits (declared in the ontology: printeps:unit and an OWL 2 datatype
// restriction), and what is wrong with a typed value — the same sentences the gateway answers with
// (gateway/ontology/values.py), so checking as you type and saving say the same thing.

export const NUMBER = {
  decimal: /^[+-]?(\d+(\.\d*)?|\.\d+)$/,
  integer: /^[+-]?\d+$/, int: /^[+-]?\d+$/, long: /^[+-]?\d+$/, short: /^[+-]?\d+$/,
  nonNegativeInteger: /^\+?\d+$/, positiveInteger: /^\+?0*[1-9]\d*$/,
  double: /^[+-]?((\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?|INF|NaN)$/,
  float: /^[+-]?((\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?|INF|NaN)$/,
};
const WHOLE = ["integer", "int", "long", "short"];
const WORDS = {
  integer: "a whole number", int: "a whole number", long: "a whole number", short: "a whole number",
  nonNegativeInteger: "a whole number, 0 or more", positiveInteger: "a whole number, 1 or more",
  decimal: "a number", double: "a number", float: "a number", boolean: "true or false", string: "text",
};

function limitsWords(limits = {}) {
  const low = limits.minInclusive;
  const high = limits.maxInclusive;
  if (low !== undefined && high !== undefined) return ` from ${low} to ${high}`;
  const parts = [];
  if (low !== undefined) parts.push(`at least ${low}`);
  if (limits.minExclusive !== undefined) parts.push(`more than ${limits.minExclusive}`);
  if (high !== undefined) parts.push(`at most ${high}`);
  if (limits.maxExclusive !== undefined) parts.push(`less than ${limits.maxExclusive}`);
  return parts.length ? `, ${parts.join(" and ")}` : "";
}

/** A plain example of a value within the limits: 1.2 (or 3 for whole numbers), else a limit. */
function defaultExample(type, limits) {
  const plain = WHOLE.includes(type) ? "3" : "1.2";
  const n = Number(plain);
  const fits = !((limits.minInclusive !== undefined && n < Number(limits.minInclusive))
    || (limits.maxInclusive !== undefined && n > Number(limits.maxInclusive))
    || (limits.minExclusive !== undefined && n <= Number(limits.minExclusive))
    || (limits.maxExclusive !== undefined && n >= Number(limits.maxExclusive)));
  return fits ? plain : (limits.minInclusive ?? limits.maxInclusive ?? plain);
}

/** "a number in metres from 0 to 5, e.g. 1.0" (the gateway's `expects` when it sent one). */
export function expectation(type, { unit = "", limits = {}, example = "", expects = "" } = {}) {
  if (expects) return expects;
  let words = (WORDS[type] || `a value of type ${type}`) + (unit ? ` in ${unit}` : "") + limitsWords(limits);
  if (!example && NUMBER[type]) example = defaultExample(type, limits);
  if (example && type !== "boolean") words += `, e.g. ${example}`;
  return words;
}

/** The value's kind, unit and limits, shown beside it: "number in metres, 0 to 5". */
export function kindWords(type, { unit = "", limits = {} } = {}) {
  const word = (WORDS[type] || type).replace(/^an? /, "");
  return word + (unit ? ` in ${unit}` : "") + limitsWords(limits).replace(/^ from /, ", ");
}

/** What is wrong with `raw` as a value of `prop` ("" when it fits). */
export function typeProblem(prop, type, raw, spec = {}) {
  const value = raw.trim();
  if (!value) return `${prop}: a value is needed`;
  const expects = expectation(type, spec);
  if (NUMBER[type] && !NUMBER[type].test(value)) return `${prop}: '${value}' is not ${expects}`;
  if (type === "boolean" && !["true", "false", "1", "0"].includes(value)) return `${prop}: '${value}' is not ${expects}`;
  if (NUMBER[type] && spec.limits) return limitProblem(prop, value, spec.unit || "", spec.limits, expects);
  return "";
}

function limitProblem(prop, value, unit, limits, expects) {
  const number = Number(value);
  if (Number.isNaN(number)) return "";
  const u = unit ? ` ${unit}` : "";
  const tests = [
    ["minInclusive", (b) => number < b, "below the least allowed,"],
    ["minExclusive", (b) => number <= b, "not more than"],
    ["maxInclusive", (b) => number > b, "above the most allowed,"],
    ["maxExclusive", (b) => number >= b, "not less than"],
  ];
  for (const [facet, broken, words] of tests) {
    const bound = limits[facet];
    if (bound !== undefined && broken(Number(bound))) return `${prop}: ${value}${u} is ${words} ${bound}${u}; give ${expects}`;
  }
  return "";
}
