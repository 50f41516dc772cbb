// What the Rules view's modules share: where a rule set's draft is kept in the browser, and the
// server's errors as the problems listed under the editor.

/** The localStorage key of rule set `name`'s undeployed draft. */
export function draftKey(name) {
  return `printeps.workbench.draft.${name}`;
}

/** Server errors ({file, line, column, message}) as problems. */
export function normalizeErrors(errors) {
  if (!Array.isArray(errors)) return [];
  return errors.filter((e) => e && (e.message || e.msg)).map((e) => ({
    file: e.file || "", line: Number(e.line) || 0, column: Number(e.column) || 0,
    severity: e.severity === "warning" ? "warning" : "error", message: String(e.message || e.msg), source: "compiler",
    sheet: e.sheet || "", cell: e.cell || "",
  }));
}
