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
  for (const entry of entries) {
    if (!scopes.has(entry.scope)) continue;
    const drl = expandWith(entry, trimmed);
    if (drl !== null) {
      return { kind: trimmed.startsWith("-") ? "constraint" : "sentence", drl, entry };
    }
  }
  return { kind: "unknown" };
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
