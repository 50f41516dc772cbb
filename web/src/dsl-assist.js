// Writing rules with help: completion, hover and quick fixes in the rule editors.
// - .dslr: typing in a when-part offers the rule set's [when]/[condition] sentences, in a then-part
//   the [then]/[consequence] ones, filtered as you type; a chosen sentence is inserted as a snippet
//   whose {placeholders} are tab stops. Hovering a sentence shows the DRL it expands to.
// - .drl: completes the fact types the rule set declares and, inside `Type( … )`, their fields.
// The sentences and types come from a `source()` callback, so they always reflect the current text
// of the .dsl/.drl editors (and GET /api/rulesets/{name}/types for deployed types).
// Quick fixes for unknown sentences are built in checks.js (nearestSentences) and shown by editor.js.

import { snippetCompletion } from "@codemirror/autocomplete";
import { EditorState } from "@codemirror/state";
import { hoverTooltip } from "@codemirror/view";
import { sectionAt, sentenceLabel, sentenceSnippet } from "./checks.js";
import { explainLine, openPattern, scopesFor } from "./assist-core.js";

export { declaredTypes, dslEntries } from "./assist-core.js";

/** The completion source of a .dslr editor: the sentences of the section the cursor is in. */
export function sentenceCompletions(source) {
  return (context) => {
    const line = context.state.doc.lineAt(context.pos);
    const before = line.text.slice(0, context.pos - line.from);
    if (before.trimStart().startsWith(">") || /^\s*(\/\/|#)/.test(before)) return null;
    const lines = context.state.doc.toString().split("\n");
    const scopes = scopesFor(sectionAt(lines, line.number));
    if (!scopes) return null;
    const typed = before.trimStart();
    if (!typed && !context.explicit) return null;
    const from = line.from + (before.length - typed.length);
    const seen = new Set();
    const options = [];
    for (const entry of source().entries) {
      if (!scopes.has(entry.scope) || seen.has(entry.sentence)) continue;
      seen.add(entry.sentence);
      options.push(snippetCompletion(sentenceSnippet(entry.sentence), {
        label: sentenceLabel(entry.sentence),
        detail: entry.scope === "when" || entry.scope === "condition" ? "condition" : entry.scope === "*" ? "sentence" : "action",
        info: `${entry.file || ".dsl"} line ${entry.line}: ${entry.code}`,
        type: "text",
        boost: entry.sentence.trim().startsWith("-") && !typed.startsWith("-") ? -10 : 0,
      }));
    }
    return { from, options, validFor: /^[^\n]*$/ };
  };
}

/** Hovering a .dslr line shows its DRL expansion. */
export function sentenceHover(source) {
  return hoverTooltip((view, pos) => {
    const line = view.state.doc.lineAt(pos);
    const lines = view.state.doc.toString().split("\n");
    const found = explainLine(lines, line.number, source().entries);
    if (!found || found.kind === "unknown") return null;
    const start = line.from + (line.text.length - line.text.trimStart().length);
    if (pos < start) return null;
    return {
      pos: start,
      end: line.to,
      above: true,
      create() {
        const dom = document.createElement("div");
        dom.className = "cm-dsl-hover";
        dom.dataset.testid = "dsl-hover";
        const title = document.createElement("div");
        title.className = "cm-dsl-hover-title";
        title.textContent = found.kind === "raw" ? "Plain DRL (passed through):"
          : found.kind === "constraint" ? "Adds to the fact on the line above:" : "The rule engine reads:";
        const code = document.createElement("pre");
        code.textContent = found.drl;
        dom.append(title, code);
        if (found.together) {
          const with_ = document.createElement("div");
          with_.className = "cm-dsl-hover-title";
          with_.textContent = "Together with it:";
          const whole = document.createElement("pre");
          whole.textContent = found.together;
          dom.append(with_, whole);
        }
        if (found.entry) {
          const from = document.createElement("div");
          from.className = "cm-dsl-hover-from";
          from.textContent = `from ${found.entry.file || "the .dsl"}, line ${found.entry.line}`;
          dom.append(from);
        }
        return { dom };
      },
    };
  }, { hoverTime: 350 });
}

/** Completion of fact types and, inside `Type( … )`, of their fields, for DRL text. */
export function drlCompletions(source) {
  return (context) => {
    const word = context.matchBefore(/[A-Za-z_$][\w$]*/);
    if (!word && !context.explicit) return null;
    const from = word ? word.from : context.pos;
    const types = source().types || {};
    const open = openPattern(context.state.doc.sliceString(Math.max(0, context.pos - 2000), context.pos));
    if (open && types[open]) {
      return {
        from,
        options: Object.entries(types[open]).map(([field, javaType]) => ({ label: field, detail: javaType, type: "property" })),
        validFor: /^[\w$]*$/,
      };
    }
    if (!word || !/^[A-Z]/.test(word.text)) {
      if (!context.explicit) return null;
    }
    return {
      from,
      options: Object.entries(types).map(([type, fields]) => ({
        label: type, type: "class", detail: "fact type",
        info: Object.entries(fields).map(([f, t]) => `${f} : ${t}`).join("\n"),
      })),
      validFor: /^[\w$]*$/,
    };
  };
}

/**
 * The editor extensions for a file: completion and hover for .dslr, completion for .drl.
 * `source()` returns {entries, types} for the rule set as it is being edited.
 */
export function assistFor(fileName, source) {
  const lower = fileName.toLowerCase();
  // One source function per editor: the completion machinery tells sources apart by identity.
  if (lower.endsWith(".dslr")) {
    const data = [{ autocomplete: sentenceCompletions(source) }];
    return [EditorState.languageData.of(() => data), sentenceHover(source)];
  }
  if (lower.endsWith(".drl")) {
    const data = [{ autocomplete: drlCompletions(source) }];
    return [EditorState.languageData.of(() => data)];
  }
  return [];
}
