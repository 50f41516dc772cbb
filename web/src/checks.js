// Checks done in the browser, instantly, before the server's compiler answers:
// - a .dslr sentence that matches no entry of the rule set's .dsl files ("phrase book") is marked
//   where it stands (Drools would pass it through unchanged and fail later with a vaguer message);
// - a .dsl line that is not an entry is marked;
// - invisible control characters (typically from pasted binary data) are marked.
// Every problem is {file, line, column, endColumn, severity, message}, lines/columns 1-based.

const ENTRY = /^\s*\[(when|condition|then|consequence|keyword|\*)\](\[[^\]]*\])?(.*)$/i;

/** Entries of one .dsl text: [{scope, sentence, pattern, line}], plus problems for bad lines. */
export function parseDsl(file, text) {
  const entries = [];
  const problems = [];
  text.split("\n").forEach((raw, index) => {
    const line = raw.replace(/\r$/, "");
    const trimmed = line.trim();
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
    entries.push({ scope, sentence, pattern, line: index + 1 });
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

function escapeRegex(text) {
  return text.replace(/[.*+?^${}()|[\]\\/]/g, "\\$&");
}

const CONDITION_SCOPES = new Set(["when", "condition", "*"]);
const CONSEQUENCE_SCOPES = new Set(["then", "consequence", "*"]);

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
      problems.push({
        file, line: index + 1, column, endColumn: line.trimEnd().length + 1, severity: "warning",
        message:
          `No sentence in the phrase book matches this ${section === "when" ? "condition" : "action"}. ` +
          "Check the wording against the .dsl file (or start the line with > to write raw DRL).",
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
