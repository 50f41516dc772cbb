// CodeMirror editors as the workbench uses them: line numbers, highlighting, search, undo, and
// diagnostics pushed from outside (the checks run on the whole rule set, not one file).

import { basicSetup } from "codemirror";
import { MergeView } from "@codemirror/merge";
import { EditorView, keymap, lineNumbers } from "@codemirror/view";
import { EditorState } from "@codemirror/state";
import { syntaxHighlighting, defaultHighlightStyle } from "@codemirror/language";
import { indentWithTab } from "@codemirror/commands";
import { setDiagnostics, lintGutter } from "@codemirror/lint";
import { snippet } from "@codemirror/autocomplete";
import { languageFor } from "./lang.js";

const theme = EditorView.theme({
  "&": { height: "100%", fontSize: "15px", backgroundColor: "#fff" },
  ".cm-scroller": { fontFamily: "ui-monospace, 'DejaVu Sans Mono', monospace", lineHeight: "1.5" },
});

/** A new editor in `parent`. onChange(text) is called after every edit of the text. */
export function createEditor(parent, { doc, fileName, readOnly = false, onChange = null, onCursor = null, label = "", extensions: extra = [] }) {
  const extensions = [
    extra,
    basicSetup,
    lintGutter(),
    keymap.of([indentWithTab]),
    theme,
    EditorView.lineWrapping,
    languageFor(fileName),
    EditorState.readOnly.of(readOnly),
    EditorView.editable.of(!readOnly),
    EditorView.contentAttributes.of({ "aria-label": label || fileName }),
  ];
  if (onChange) {
    extensions.push(EditorView.updateListener.of((update) => {
      if (update.docChanged) onChange(update.state.doc.toString());
    }));
  }
  if (onCursor) {
    extensions.push(EditorView.updateListener.of((update) => {
      if (update.selectionSet) onCursor(update.state.doc.lineAt(update.state.selection.main.head).number);
    }));
  }
  return new EditorView({ parent, state: EditorState.create({ doc, extensions }) });
}

/** Scroll line `number` into view ("start" or "center"), without moving the reader's cursor. */
export function scrollToLine(view, number, where = "center") {
  const doc = view.state.doc;
  if (!doc.length) return;
  const line = doc.line(Math.min(Math.max(number, 1), doc.lines));
  view.dispatch({ effects: EditorView.scrollIntoView(line.from, { y: where, yMargin: 8 }) });
}

/** Replace the whole text (e.g. discard edits) as one undoable change. */
export function setText(view, text) {
  view.dispatch({ changes: { from: 0, to: view.state.doc.length, insert: text } });
}

/** Show problems ({line, column, endColumn?, severity, message}) inline in the editor. */
export function showProblems(view, problems) {
  const doc = view.state.doc;
  const diagnostics = problems.filter((p) => p.line > 0).map((p) => toDiagnostic(doc, p));
  view.dispatch(setDiagnostics(view.state, diagnostics));
}

function toDiagnostic(doc, problem) {
  const line = doc.line(Math.min(problem.line, doc.lines));
  let from = line.from;
  let to = line.to;
  if (problem.column > 0) {
    from = Math.min(line.from + problem.column - 1, line.to);
    to = problem.endColumn > problem.column
      ? Math.min(line.from + problem.endColumn - 1, line.to)
      : quotedEnd(doc, line, from, problem.message) || wordEnd(doc, line, from);
  }
  if (to <= from) {
    if (from >= line.to && from > line.from) from -= 1; // past the end of the line: mark its last character
    to = Math.min(from + 1, line.to);
  }
  const diagnostic = { from, to, severity: problem.severity || "error", message: problem.message, source: problem.source };
  if (problem.fixes && problem.fixes.length) {
    // Quick fixes: replace the marked sentence with a known one, its holes as tab stops.
    diagnostic.actions = problem.fixes.map((fix) => ({
      name: fix.label,
      apply(view, at, end) {
        const line = view.state.doc.lineAt(at);
        const start = line.from + (line.text.length - line.text.trimStart().length);
        snippet(fix.template)(view, null, start, Math.max(end, line.from + line.text.trimEnd().length));
        view.focus();
      },
    }));
  }
  return diagnostic;
}

/** When the message quotes the text found at `from` ("mismatched input ')'"), mark exactly that. */
function quotedEnd(doc, line, from, message) {
  const rest = doc.sliceString(from, line.to);
  for (const match of String(message || "").matchAll(/'([^'\n]+)'/g)) {
    if (rest.startsWith(match[1])) return from + match[1].length;
  }
  return 0;
}

function wordEnd(doc, line, from) {
  const rest = doc.sliceString(from, line.to);
  const word = /^[\w$.]+/.exec(rest);
  return from + (word ? word[0].length : Math.min(1, rest.length));
}

/** Move the cursor to a problem and show it. */
export function reveal(view, problem) {
  const doc = view.state.doc;
  const line = doc.line(Math.min(Math.max(problem.line, 1), doc.lines));
  const pos = Math.min(line.from + Math.max(problem.column - 1, 0), line.to);
  view.dispatch({ selection: { anchor: pos }, effects: EditorView.scrollIntoView(pos, { y: "center" }) });
  view.focus();
}

/** A read-only side-by-side line diff of `older` (left) and `newer` (right) in a new element, as
 * every history in the workbench shows one (rule files, knowledge, queries and mappings):
 * CodeMirror's MergeView, unchanged stretches folded. `fileName` adds that file's highlighting. */
export function textDiff(older, newer, { fileName = null, margin = 2, minSize = 4 } = {}) {
  const host = document.createElement("div");
  host.className = "merge-host";
  const setup = [lineNumbers(), EditorState.readOnly.of(true), EditorView.editable.of(false), EditorView.lineWrapping,
    ...(fileName ? [syntaxHighlighting(defaultHighlightStyle), languageFor(fileName)] : [])];
  new MergeView({ a: { doc: older, extensions: setup }, b: { doc: newer, extensions: setup }, parent: host,
    collapseUnchanged: { margin, minSize } });
  return host;
}
