// Checks done in the browser, instantly, before the server's compiler answers:
// - a .dslr sentence that matches no entry of the rule set's .dsl files ("phrase book") is marked
//   where it stands (Drools would pass it through unchanged and fail later with a vaguer message);
// - a .dsl line that is not an entry is marked;
// - invisible control characters (typically from pasted binary data) are marked.
// Every problem is {file, line, column, endColumn, severity, message, fixes?}, lines/columns 1-based;
// `fixes` ([{label, template}]) are the nearest known sentences, offered as quick fixes.

const ENTRY = /^\s*\[(when|condition|then|consequence|keyword|\*)\](\[[^\]]*\])?(.*)$/i;

/** Entries of one .dsl text: [{scope, sentence, pattern, code, holes, line, topic}], plus problems for bad lines. */
export function parseDsl(file, text) {
  const entries = [];
  const problems = [];
  let topic = ""; // the heading above ("# --- The party at the entrance ---"): what the entries are about
  text.split("\n").forEach((raw, index) => {
    const line = raw.replace(/\r$/, "");
    const trimmed = line.trim();
    const heading = /^(?:#|\/\/)\s*-{2,}\s*(.*?)\s*-*\s*$/.exec(trimmed);
    if (heading && heading[1]) topic = heading[1];
    if (!trimmed || trimmed.startsWith("#") || trimmed.startsWith("//")) return;
    const match = ENTRY.exec(line);
    const split = match ? splitEntry(match[3]) : null;
    if (!match || !split) {
      problems.push({
        file, line: index + 1, column: line.length - line.trimStart().length + 1, endColumn: line.length + 1,
        severity: "error",
        message: 'This line is not a phrase-book entry. Write it like: [when]There is a customer=c: Customer()',
      });
      return;
    }
    const scope = match[1].toLowerCase();
    const sentence = split.sentence.trim();
    let pattern;
    try {
      pattern = sentencePattern(sentence);
    } catch (err) {
      problems.push({
        file, line: index + 1, column: 1, endColumn: line.length + 1, severity: "error",
        message: `The sentence pattern is not valid: ${err.message}`,
      });
      return;
    }
    entries.push({ scope, sentence, pattern, code: split.code.trim(), holes: sentenceHoles(sentence), line: index + 1, topic });
  });
  return { entries, problems };
}

/** "sentence=code" split at the first "=" that is not escaped as "\=" (null when there is none). */
function splitEntry(rest) {
  for (let i = 0; i < rest.length; i++) {
    if (rest[i] === "\\") i++;
    else if (rest[i] === "=") return { sentence: rest.slice(0, i), code: rest.slice(i + 1) };
  }
  return null;
}

/** A regular expression matching a whole sentence line; {name} and {name:regex} are the holes. */
export function sentencePattern(sentence) {
  let source = "";
  let i = 0;
  while (i < sentence.length) {
    const ch = sentence[i];
    if (ch === "\\" && i + 1 < sentence.length) {
      source += escapeRegex(sentence[i + 1]);
      i += 2;
    } else if (ch === "{") {
      const close = sentence.indexOf("}", i);
      if (close < 0) throw new Error(`"{" at column ${i + 1} is never closed`);
      const hole = sentence.slice(i + 1, close);
      const colon = hole.indexOf(":");
      source += colon >= 0 ? `(${hole.slice(colon + 1)})` : "(.*?)";
      i = close + 1;
    } else if (/\s/.test(ch)) {
      source += "\\s+";
      while (i < sentence.length && /\s/.test(sentence[i])) i++;
    } else {
      source += escapeRegex(ch);
      i++;
    }
  }
  return new RegExp(`^\\s*${source}\\s*$`);
}

/** The {name} / {name:regex} holes of a sentence, in order: [{name, regex, quoted}]. */
export function sentenceHoles(sentence) {
  const holes = [];
  for (let i = 0; i < sentence.length; i++) {
    if (sentence[i] === "\\") {
      i++;
      continue;
    }
    if (sentence[i] !== "{") continue;
    const close = sentence.indexOf("}", i);
    if (close < 0) break;
    const hole = sentence.slice(i + 1, close);
    const colon = hole.indexOf(":");
    holes.push({
      name: colon >= 0 ? hole.slice(0, colon) : hole,
      regex: colon >= 0 ? hole.slice(colon + 1) : "",
      quoted: sentence[i - 1] === '"' && sentence[close + 1] === '"',
    });
    i = close;
  }
  return holes;
}

/** The sentence as readers see it: {n:\d+} shown as {n}, escapes removed. */
export function sentenceLabel(sentence) {
  return sentence.replace(/\{([^}:]*):[^}]*\}/g, "{$1}").replace(/\\(.)/g, "$1");
}

/**
 * A CodeMirror snippet template for a sentence: every hole a tab stop, pre-filled with `values[i]`
 * when given (else the hole's name). Literal braces are escaped as the snippet syntax wants.
 */
export function sentenceSnippet(sentence, values = []) {
  let out = "";
  let hole = 0;
  for (let i = 0; i < sentence.length; i++) {
    const ch = sentence[i];
    if (ch === "\\" && i + 1 < sentence.length) {
      const next = sentence[++i];
      out += next === "{" || next === "}" ? `\\${next}` : next;
    } else if (ch === "{") {
      const close = sentence.indexOf("}", i);
      const inner = sentence.slice(i + 1, close < 0 ? sentence.length : close);
      const name = inner.split(":")[0];
      const value = values[hole] !== undefined && values[hole] !== null ? String(values[hole]) : name;
      hole++;
      out += `\${${hole}:${value.replace(/[{}]/g, "")}}`;
      i = close < 0 ? sentence.length : close;
    } else if (ch === "}") {
      out += "\\}";
    } else out += ch;
  }
  return out;
}

/** The sentence with its holes filled by `values` (their names where missing): plain text. */
export function fillSentence(sentence, values = []) {
  let hole = 0;
  return sentenceLabel(sentence).replace(/\{([^}]*)\}/g, (_, name) => {
    const value = values[hole++];
    return value !== undefined && value !== null ? String(value) : `{${name}}`;
  });
}

/**
 * The DRL a sentence line stands for, with what the line wrote in the holes copied into the
 * entry's code; null when the entry does not match the line.
 */
export function expandWith(entry, lineText) {
  const match = entry.pattern.exec(lineText);
  if (!match) return null;
  const values = {};
  entry.holes.forEach((hole, i) => {
    values[hole.name] = match[i + 1];
  });
  let out = "";
  const code = entry.code;
  for (let i = 0; i < code.length; i++) {
    const ch = code[i];
    if (ch === "\\" && i + 1 < code.length) {
      out += code[++i];
    } else if (ch === "{") {
      const close = code.indexOf("}", i);
      const name = code.slice(i + 1, close < 0 ? code.length : close).split(":")[0];
      out += name in values ? values[name] : code.slice(i, close + 1);
      i = close < 0 ? code.length : close;
    } else out += ch;
  }
  return out;
}

/** The values a line holds that could fill a sentence's holes: quoted texts, then numbers, then words. */
function lineValues(text) {
  const quoted = [...text.matchAll(/"([^"]*)"/g)].map((m) => m[1]);
  const rest = text.replace(/"[^"]*"/g, " ");
  const numbers = [...rest.matchAll(/-?\d+(?:\.\d+)?/g)].map((m) => m[0]);
  return { quoted, numbers };
}

/** A sentence's holes filled from what the misspelt line holds (quoted texts into quoted holes,
 * numbers into the others), for a quick fix that keeps what the author meant. */
export function guessValues(entry, text) {
  const { quoted, numbers } = lineValues(text);
  let q = 0;
  let n = 0;
  return entry.holes.map((hole) => {
    if (hole.quoted && q < quoted.length) return quoted[q++];
    if (!hole.quoted && n < numbers.length && (!hole.regex || new RegExp(`^(?:${hole.regex})$`).test(numbers[n]))) return numbers[n++];
    return null;
  });
}

/** Edit distance (Levenshtein), case-insensitive. */
export function distance(a, b) {
  a = a.toLowerCase();
  b = b.toLowerCase();
  const row = Array.from({ length: b.length + 1 }, (_, j) => j);
  for (let i = 1; i <= a.length; i++) {
    let prev = row[0];
    row[0] = i;
    for (let j = 1; j <= b.length; j++) {
      const tmp = row[j];
      row[j] = Math.min(row[j] + 1, row[j - 1] + 1, prev + (a[i - 1] === b[j - 1] ? 0 : 1));
      prev = tmp;
    }
  }
  return row[b.length];
}

/**
 * The known sentences nearest to a line no sentence matches, as quick fixes
 * [{label, template, entry}], nearest first (at most `limit`, and only reasonably near ones).
 */
export function nearestSentences(text, entries, scopes, limit = 3) {
  const trimmed = text.trim();
  const continuation = trimmed.startsWith("-");
  const scored = [];
  const seen = new Set();
  for (const entry of entries) {
    if (!scopes.has(entry.scope) || entry.sentence.trim().startsWith("-") !== continuation) continue;
    const values = guessValues(entry, trimmed);
    const label = fillSentence(entry.sentence, values);
    if (seen.has(label)) continue;
    seen.add(label);
    const d = distance(trimmed, label);
    if (d <= Math.max(4, Math.ceil(Math.max(trimmed.length, label.length) * 0.45))) {
      scored.push({ d, label, template: sentenceSnippet(entry.sentence, values), entry });
    }
  }
  scored.sort((a, b) => a.d - b.d || a.label.localeCompare(b.label));
  // Only those about as near as the nearest: a clear typo gets one fix, not three guesses.
  const best = scored.length ? scored[0].d : 0;
  return scored.filter((s) => s.d <= best + Math.max(3, best / 2)).slice(0, limit)
    .map(({ label, template, entry }) => ({ label, template, entry }));
}

/** Which part of a rule line `number` (1-based) of a .dslr text is in: "when", "then" or null. */
export function sectionAt(lines, number) {
  let section = null;
  let inBlockComment = false;
  for (let n = 1; n < number && n <= lines.length; n++) {
    const trimmed = lines[n - 1].trim();
    if (inBlockComment) {
      if (trimmed.includes("*/")) inBlockComment = false;
      continue;
    }
    if (trimmed.startsWith("/*")) {
      inBlockComment = !trimmed.includes("*/");
      continue;
    }
    const word = trimmed.split(/\s+/)[0];
    if (word === "rule") section = null;
    else if (trimmed === "when") section = "when";
    else if (trimmed === "then") section = "then";
    else if (trimmed === "end") section = null;
  }
  return section;
}

export const CONDITION_SCOPES = new Set(["when", "condition", "*"]);
export const CONSEQUENCE_SCOPES = new Set(["then", "consequence", "*"]);

function escapeRegex(text) {
  return text.replace(/[.*+?^${}()|[\]\\/]/g, "\\$&");
}

/** Sentences of a .dslr text that no entry matches, as warnings at their place. */
export function unmatchedSentences(file, text, entries) {
  const problems = [];
  if (!entries.length) return problems;
  let section = "outside"; // outside | when | then
  let inBlockComment = false;
  text.split("\n").forEach((raw, index) => {
    const line = raw.replace(/\r$/, "");
    const trimmed = line.trim();
    if (inBlockComment) {
      if (trimmed.includes("*/")) inBlockComment = false;
      return;
    }
    if (trimmed.startsWith("/*")) {
      inBlockComment = !trimmed.includes("*/");
      return;
    }
    const word = trimmed.split(/\s+/)[0];
    if (word === "rule") section = "header";
    else if (word === "when" && trimmed === "when") section = "when";
    else if (word === "then" && trimmed === "then") section = "then";
    else if (word === "end" && trimmed === "end") section = "outside";
    if (section !== "when" && section !== "then") return;
    if (trimmed === "when" || trimmed === "then") return;
    if (!trimmed || trimmed.startsWith("#") || trimmed.startsWith("//") || trimmed.startsWith(">")) return;
    const scopes = section === "when" ? CONDITION_SCOPES : CONSEQUENCE_SCOPES;
    const known = entries.some((e) => scopes.has(e.scope) && e.pattern.test(trimmed));
    if (!known) {
      const column = line.length - line.trimStart().length + 1;
      const fixes = nearestSentences(trimmed, entries, scopes);
      problems.push({
        file, line: index + 1, column, endColumn: line.trimEnd().length + 1, severity: "warning",
        message:
          `No sentence in the phrase book matches this ${section === "when" ? "condition" : "action"}. ` +
          (fixes.length ? `Did you mean “${fixes[0].label}”? ` : "") +
          "Check the wording against the .dsl file (or start the line with > to write raw DRL).",
        fixes: fixes.map(({ label, template }) => ({ label, template })),
      });
    }
  });
  return problems;
}

// Control characters other than tab, newline and carriage return: a sign of pasted binary data.
const CONTROL = /[\u0000-\u0008\u000b\u000c\u000e-\u001f\u007f\ufffd]/g;

/** Invisible control characters, one problem per line that has any. */
export function controlCharacters(file, text) {
  const problems = [];
  text.split("\n").forEach((line, index) => {
    CONTROL.lastIndex = 0;
    const match = CONTROL.exec(line);
    if (!match) return;
    const code = match[0].charCodeAt(0).toString(16).toUpperCase().padStart(4, "0");
    problems.push({
      file, line: index + 1, column: match.index + 1, endColumn: match.index + 2, severity: "error",
      message: `Invisible character U+${code} here (pasted binary data?). Delete it: rules must be plain text.`,
    });
  });
  return problems;
}

/** All browser-side problems of a rule set's files ({name: text}). */
export function localProblems(files) {
  const problems = [];
  const entries = [];
  for (const [name, text] of Object.entries(files)) {
    problems.push(...controlCharacters(name, text));
    if (name.toLowerCase().endsWith(".dsl")) {
      const parsed = parseDsl(name, text);
      entries.push(...parsed.entries);
      problems.push(...parsed.problems);
    }
  }
  for (const [name, text] of Object.entries(files)) {
    if (name.toLowerCase().endsWith(".dslr")) problems.push(...unmatchedSentences(name, text, entries));
  }
  return problems;
}
