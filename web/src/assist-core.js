// The plain logic behind completion and hover (no editor code, so node's test runner can check it):
// a rule set's DSL sentences and declared types, what a .dslr line expands to, which pattern the
// cursor of a DRL text is in.

import { CONDITION_SCOPES, CONSEQUENCE_SCOPES, expandWith, parseDsl, sectionAt } from "./checks.js";

/** The sentences a section may use: when -> [when]/[condition], then -> [then]/[consequence]. */
export function scopesFor(section) {
  return section === "when" ? CONDITION_SCOPES : section === "then" ? CONSEQUENCE_SCOPES : null;
}

/** DSL entries of every .dsl file of a rule set's files ({name: text}). */
export function dslEntries(files) {
  const entries = [];
  for (const [name, text] of Object.entries(files)) {
    if (name.toLowerCase().endsWith(".dsl")) entries.push(...parseDsl(name, text).entries.map((e) => ({ ...e, file: name })));
  }
  return entries;
}

/** Declared types of the .drl texts: {Type: {field: javaType}} (merged over the server's `types`). */
export function declaredTypes(files, types = {}) {
  const out = {};
  for (const [type, fields] of Object.entries(types || {})) out[type] = { ...fields };
  for (const [name, text] of Object.entries(files)) {
    if (!name.toLowerCase().endsWith(".drl")) continue;
    for (const block of text.matchAll(/^\s*declare\s+([A-Za-z_][\w]*)([\s\S]*?)^\s*end\b/gm)) {
      const fields = out[block[1]] || {};
      for (const field of block[2].matchAll(/^\s*([A-Za-z_]\w*)\s*:\s*([\w.<>[\]]+)/gm)) fields[field[1]] = field[2];
      out[block[1]] = fields;
    }
  }
  return out;
}

/** What a .dslr line stands for in DRL (null when it is no sentence line). */
export function explainLine(lines, number, entries) {
  const text = lines[number - 1] || "";
  const trimmed = text.trim();
  const section = sectionAt(lines, number);
  const scopes = scopesFor(section);
  if (!scopes || !trimmed || trimmed === "when" || trimmed === "then" || /^(\/\/|#)/.test(trimmed)) return null;
  if (trimmed.startsWith(">")) return { kind: "raw", drl: trimmed.slice(1).trim() };
  const found = expandLine(trimmed, entries, scopes);
  if (!found) return { kind: "unknown" };
  if (!trimmed.startsWith("-")) return { kind: "sentence", ...found };
  // A "- …" line adds constraints to the pattern of the sentence above it: show both together.
  let n = number - 1;
  while (n >= 1 && (lines[n - 1] || "").trim().startsWith("-")) n--;
  const above = n >= 1 ? (lines[n - 1] || "").trim() : "";
  const pattern = above && sectionAt(lines, n) === section ? expandLine(above, entries, scopes) : null;
  const together = pattern && /\)\s*$/.test(pattern.drl)
    ? addConstraints(pattern.drl, lines, number, entries, scopes, section) : null;
  return { kind: "constraint", ...found, together };
}

function expandLine(text, entries, scopes) {
  for (const entry of entries) {
    if (!scopes.has(entry.scope)) continue;
    const drl = expandWith(entry, text);
    if (drl !== null) return { drl, entry };
  }
  return null;
}

/** The pattern above with the constraints of every "- …" line down to line `number` added. */
function addConstraints(pattern, lines, number, entries, scopes, section) {
  let start = number;
  while (start > 1 && (lines[start - 2] || "").trim().startsWith("-")) start--;
  const constraints = [];
  for (let n = start; n <= number; n++) {
    const found = expandLine((lines[n - 1] || "").trim(), entries, scopes);
    if (found && sectionAt(lines, n) === section) constraints.push(found.drl);
  }
  const close = pattern.lastIndexOf(")");
  const inner = pattern.slice(pattern.indexOf("(") + 1, close).trim();
  return pattern.slice(0, close) + (inner ? ", " : "") + constraints.join(", ") + pattern.slice(close);
}

/** The type name of the innermost `Type(` still open at the end of `text` (or ""). */
export function openPattern(text) {
  let depth = 0;
  for (let i = text.length - 1; i >= 0; i--) {
    const ch = text[i];
    if (ch === ")") depth++;
    else if (ch === "(") {
      if (depth === 0) {
        const name = /([A-Za-z_][\w.]*)\s*$/.exec(text.slice(0, i));
        return name ? name[1].split(".").pop() : "";
      }
      depth--;
    } else if (ch === "\n" && /^\s*(then|end|rule)\b/.test(text.slice(i + 1))) return "";
  }
  return "";
}
