// The plain logic behind the owner's two rule tools (no DOM, so node's test runner checks it):
// finding and replacing words in the rules' sentences, and writing a new rule from chosen sentences.
// Why: an owner changes "bow" into "deep bow" in every greeting, or adds a rule, without the
// editor's keyboard shortcuts and without writing rule syntax (the tools write `rule … end`).

/** Files whose text holds the rules' sentences and code (not the tests, the dictionary or examples). */
export function isRuleText(fileName) {
  return /\.(dslr|drl)$/i.test(fileName);
}

/** Every place `find` stands in `text` (exact, case-sensitive): [{from, to, line}] (line 1-based). */
export function findAll(text, find) {
  const out = [];
  if (!find) return out;
  let line = 1;
  let counted = 0;
  for (let at = text.indexOf(find); at >= 0; at = text.indexOf(find, at + find.length)) {
    for (; counted < at; counted++) if (text[counted] === "\n") line++;
    out.push({ from: at, to: at + find.length, line });
  }
  return out;
}

/** The rule (from the outline: [{name, file, line}]) a line of a file belongs to (null: none). */
export function ruleAt(rules, file, line) {
  let best = null;
  for (const rule of rules) {
    if (rule.file === file && rule.line && rule.line <= line && (!best || rule.line > best.line)) best = rule;
  }
  return best;
}

/** A sentence as the menu shows it: each hole ({text}, {n:\d+}) as "…", escapes dropped. */
export function sentenceShown(sentence) {
  return sentence.replace(/\{[^}]*\}/g, "…").replace(/\\(.)/g, "$1");
}

/** The parts of a sentence: literal text and holes, in order ([{text} | {hole: {name, regex, quoted}}]). */
export function sentenceParts(sentence) {
  const parts = [];
  let literal = "";
  for (let i = 0; i < sentence.length; i++) {
    if (sentence[i] === "\\" && i + 1 < sentence.length) {
      literal += sentence[++i];
      continue;
    }
    const close = sentence[i] === "{" ? sentence.indexOf("}", i) : -1;
    if (close < 0) {
      literal += sentence[i];
      continue;
    }
    if (literal) parts.push({ text: literal });
    literal = "";
    const hole = sentence.slice(i + 1, close);
    const colon = hole.indexOf(":");
    parts.push({ hole: { name: colon >= 0 ? hole.slice(0, colon) : hole, regex: colon >= 0 ? hole.slice(colon + 1) : "",
      quoted: sentence[i - 1] === '"' && sentence[close + 1] === '"' } });
    i = close;
  }
  if (literal) parts.push({ text: literal });
  return parts;
}

/** What is wrong with a hole's value, in words ("" when it fits). */
export function holeProblem(hole, value) {
  if (!value.trim()) return `fill in the ${hole.name}`;
  if (hole.regex && !new RegExp(`^(?:${hole.regex})$`).test(value)) {
    return hole.regex === "\\d+" ? `the ${hole.name} is a whole number, e.g. 2` : `the ${hole.name} does not fit ${hole.regex}`;
  }
  if (hole.quoted && value.includes('"')) return `the ${hole.name} cannot contain a double quote (")`;
  if (/[\n\r]/.test(value)) return `the ${hole.name} is one line`;
  return "";
}

/** A sentence with its holes filled ({name: value}). */
export function fillSentence(sentence, values) {
  return sentenceParts(sentence).map((p) => (p.hole ? values[p.hole.name] ?? "" : p.text)).join("");
}

/** What keeps a new rule from being written (a list of problems in words; empty: it can be). */
export function newRuleProblems(name, when, then, existing) {
  const problems = [];
  if (!name.trim()) problems.push("Give the rule a name.");
  else if (/["\n]/.test(name)) problems.push("The name cannot contain a double quote or a line break.");
  else if (existing.includes(name.trim())) problems.push(`There is already a rule named “${name.trim()}”.`);
  if (!then.length) problems.push("Add at least one action under Then.");
  for (const line of [...when, ...then]) if (line.problem) problems.push(`“${line.shown}”: ${line.problem}.`);
  return problems;
}

/** The rule as .dslr text (a blank line before it), from its name and filled sentences. */
export function ruleText(name, when, then) {
  const lines = ["", `rule "${name.trim()}"`, "when", ...when.map((s) => `    ${s}`), "then", ...then.map((s) => `    ${s}`), "end", ""];
  return lines.join("\n");
}

/** How many sentence lines of the rule texts each entry stands for (a Map entry -> count). */
export function sentenceUse(entries, files) {
  const lines = [];
  for (const [file, text] of Object.entries(files)) if (/\.dslr$/i.test(file)) lines.push(...text.split("\n").map((l) => l.trim()));
  return new Map(entries.map((e) => [e, lines.filter((l) => l && e.pattern.test(l)).length]));
}

export const MOST_USED = 3;

/**
 * A sentence menu's groups, as a guided rule editor shows them: "Most used" first (the few the rules
 * use most), then the phrase book's own sections (its "# --- heading ---" lines), and the lines that
 * narrow the sentence above ("- of exactly … customers") last. Each sentence once per group:
 * [{label, entries}].
 */
export function sentenceGroups(entries, use = new Map()) {
  const seen = new Set();
  const unique = entries.filter((e) => !seen.has(e.sentence) && seen.add(e.sentence));
  const narrowing = (e) => e.sentence.startsWith("-");
  const most = unique.filter((e) => !narrowing(e) && (use.get(e) || 0) > 1)
    .sort((a, b) => (use.get(b) || 0) - (use.get(a) || 0)).slice(0, MOST_USED);
  const groups = most.length ? [{ label: "Most used", entries: most }] : [];
  const byTopic = new Map();
  for (const e of unique.filter((x) => !narrowing(x))) {
    const label = e.topic || "Other sentences";
    if (!byTopic.has(label)) byTopic.set(label, []);
    byTopic.get(label).push(e);
  }
  for (const [label, mine] of byTopic) groups.push({ label, entries: mine });
  const narrow = unique.filter(narrowing);
  if (narrow.length) groups.push({ label: "Narrowing the sentence above", entries: narrow });
  return groups;
}

/** The `$names` a phrase-book entry's code binds (`$e: Entrance()`) and the ones it only uses. */
function variables(entry) {
  const bound = new Set([...entry.code.matchAll(/(\$\w+)\s*:(?!:)/g)].map((m) => m[1]));
  const used = new Set([...entry.code.matchAll(/\$\w+/g)].map((m) => m[0]).filter((v) => !bound.has(v)));
  return { bound, used };
}

/**
 * The conditions a sentence needs before it (in order): for each `$name` its code uses that none of
 * `chosen` binds, the one condition of the phrase book that binds it ("Everyone in the party has a
 * type" is about the party that "There is a party at the entrance" finds). A name bound by several
 * conditions is left to the author.
 */
export function neededConditions(entry, chosen, conditions) {
  const out = [];
  const have = new Set(chosen.flatMap((e) => [...variables(e).bound]));
  const visit = (e) => {
    for (const name of variables(e).used) {
      if (have.has(name)) continue;
      const binders = conditions.filter((c) => variables(c).bound.has(name));
      if (binders.length !== 1) continue;
      have.add(name);
      visit(binders[0]);
      out.push(binders[0]);
    }
  };
  visit(entry);
  return out;
}

/** A name for a rule left unnamed: what it does (its first action), unique among `existing`. */
export function defaultRuleName(then, existing) {
  const base = (then[0] || "New rule").replace(/"([^"]*)"/g, "“$1”").replace(/"/g, "”").replace(/\s+/g, " ").trim();
  let name = base;
  for (let n = 2; existing.includes(name); n++) name = `${base} (${n})`;
  return name;
}
