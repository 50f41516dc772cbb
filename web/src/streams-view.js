// The Streams section: the continuous queries (C-SPARQL) and the RDF mappings (message → triples)
// the stream reasoning runs on, edited as text. Check/Validate run every check of a save and change
// nothing; Save makes a new version, live at once; History rolls back. A bad save keeps the
// author's text and leaves what runs untouched. Callers (non-authors) see the same pages read-only.
//
// Routes: #/streams (overview) · #/streams/queries/<name> · #/streams/mappings/<name>
//         #/streams/new/query · #/streams/new/mapping (authors: a new one from a template)

import { h, fill, when } from "./dom.js";
import { api } from "./api.js";
import { createEditor, showProblems, reveal, textDiff } from "./editor.js";
import "./streams-view.css";

const RESULTS_SHOWN = 10;
const NEW_QUERY = `REGISTER QUERY CustomersNow AS
PREFIX printeps: <http://printeps.org/cafe/entrance/>
SELECT (COUNT(DISTINCT ?s) AS ?customers)
FROM STREAM <http://printeps.org/cafe/entrance> [RANGE 5s STEP 1s]
WHERE { ?s a printeps:Customer . }
`;
const NEW_MAPPING = `# How one message becomes RDF; the fields named here must be in the message.
subject: "printeps:reading_{id}"
type: printeps:Reading
fields:
  value: printeps:value
`;
const RESULTS_REFRESH_MS = 5000;

export async function showStreams(main, ctx, name, params) {
  const [kind, item] = splitName(name);
  const lists = await loadLists();
  sidebar(ctx, lists, kind, item);
  if (kind === "queries" && item) return showQuery(main, ctx, item);
  if (kind === "mappings" && item) return showMapping(main, ctx, item, params);
  if (kind === "new" && item === "query") return showQuery(main, ctx, null);
  if (kind === "new" && item === "mapping") return showMapping(main, ctx, null, params);
  return showOverview(main, ctx, lists);
}

/** "queries/X" -> ["queries", "X"]; a mapping name may itself hold dots and colons, never "/". */
function splitName(name) {
  const at = (name || "").indexOf("/");
  if (at < 0) return [name || "", ""];
  return [name.slice(0, at), name.slice(at + 1)];
}

/** Readable addresses (#/streams/queries/<name>): the kind stays a path step, the name is encoded. */
const queryHref = (ctx, name) => `${ctx.href("streams")}/queries/${encodeURIComponent(name)}`;
const mappingHref = (ctx, name) => `${ctx.href("streams")}/mappings/${encodeURIComponent(name)}`;

/** REST paths of one query / mapping; names are always encoded, never trusted as path pieces. */
const queryPath = (name, rest = "") => `/api/queries/${encodeURIComponent(name)}${rest}`;
const mappingPath = (name, rest = "") => `/api/mappings/${encodeURIComponent(name)}${rest}`;

async function loadLists() {
  const [queries, mappings] = await Promise.allSettled([api("GET", "/api/queries"), api("GET", "/api/mappings")]);
  return {
    queries: queries.status === "fulfilled" ? queries.value.queries.slice().sort((a, b) => a.name.localeCompare(b.name)) : [],
    mappings: mappings.status === "fulfilled" ? mappings.value : [],
    error: [queries, mappings].filter((r) => r.status === "rejected").map((r) => r.reason.message).join(" "),
  };
}

// ---------------------------------------------------------------- the sidebar

function sidebar(ctx, lists, kind, item) {
  const entry = (href, label, meta, active, testid) => h("li", { class: active ? "streams-item active" : "streams-item" },
    h("a", { href, "data-testid": testid, "aria-current": active ? "page" : null },
      h("span", { class: "name" }, label), h("span", { class: "meta" }, meta)));
  ctx.setSidebar("Streams", [
    h("li", { class: "streams-group", id: "streams-queries-title" }, "Continuous queries"),
    ...lists.queries.map((q) => entry(queryHref(ctx, q.name), q.name, q.version ? `version ${q.version}` : "not stored",
      kind === "queries" && item === q.name, `query-link-${q.name}`)),
    h("li", { class: "streams-group", id: "streams-mappings-title" }, "RDF mappings"),
    ...lists.mappings.map((m) => entry(mappingHref(ctx, m.name), m.name, m.version ? `version ${m.version}` : "built-in",
      kind === "mappings" && item === m.name, `mapping-link-${m.name}`)),
    lists.error ? h("li", { class: "message error" }, lists.error) : null,
  ]);
}

// ---------------------------------------------------------------- overview

function showOverview(main, ctx, lists) {
  fill(main, h("section", { class: "streams" },
    h("div", { class: "title-row" }, h("h1", {}, "Streams"),
      ctx.isAuthor() ? [h("a", { class: "button secondary", href: `${ctx.href("streams")}/new/query`, "data-testid": "new-query" }, "New query"),
        h("a", { class: "button secondary", href: `${ctx.href("streams")}/new/mapping`, "data-testid": "new-mapping" }, "New mapping")] : null),
    h("p", { class: "hint" }, "Sensor messages become RDF through the mappings; the continuous queries watch windows of those streams and feed their results to the rules. Open one to read or change it: every save is checked first and kept as a version."),
    lists.error ? h("div", { class: "message error", role: "alert" }, lists.error) : null,
    h("h2", {}, "Continuous queries"),
    lists.queries.length ? h("table", { class: "streams-table", "data-testid": "queries" },
      h("thead", {}, h("tr", {}, ["Query", "Windows", "Report", "Feeds", "Version"].map((t) => h("th", { scope: "col" }, t)))),
      h("tbody", {}, lists.queries.map((q) => h("tr", {},
        h("td", {}, h("a", { href: queryHref(ctx, q.name) }, q.name)),
        h("td", {}, describeWindows(q.windows)),
        h("td", {}, describeReport(q.report)),
        h("td", {}, q.binding ? `${q.binding.ruleset} (${q.binding.fact_type})` : q.output_stream ? `stream <${q.output_stream}>` : "—"),
        h("td", {}, q.version ?? "—")))))
      : h("p", { class: "muted" }, "No continuous queries are registered."),
    h("h2", {}, "RDF mappings"),
    lists.mappings.length ? h("table", { class: "streams-table", "data-testid": "mappings" },
      h("thead", {}, h("tr", {}, ["Mapping", "Message type", "Version"].map((t) => h("th", { scope: "col" }, t)))),
      h("tbody", {}, lists.mappings.map((m) => h("tr", {},
        h("td", {}, h("a", { href: mappingHref(ctx, m.name) }, m.name)),
        h("td", {}, m.message_type || "—"),
        h("td", {}, m.version ?? "built-in")))))
      : h("p", { class: "muted" }, "No mappings.")));
  return {};
}

function describeWindows(windows = []) {
  return windows.map((w) => {
    const size = w.triples ? `${w.triples} triples` : `${ms(w.range_ms)} every ${ms(w.step_ms)}`;
    return `${shortIri(w.stream)} [${size}]`;
  }).join(", ") || "—";
}

function describeReport(report) {
  if (!report) return "—";
  const text = { window_close: "on window close", content_change: "on content change", periodic: `every ${ms(report.period_ms)}` }[report.trigger] || report.trigger;
  return text + (report.non_empty ? ", non-empty only" : "");
}

/** The gateway's default prefixes (gateway/rdf/terms.py DEFAULT_PREFIXES): IRIs read as prefix:local. */
const PREFIXES = [
  ["printeps:", "http://printeps.org/cafe/entrance/"],
  ["rdf:", "http://www.w3.org/1999/02/22-rdf-syntax-ns#"],
  ["rdfs:", "http://www.w3.org/2000/01/rdf-schema#"],
  ["owl:", "http://www.w3.org/2002/07/owl#"],
  ["xsd:", "http://www.w3.org/2001/XMLSchema#"],
];

/** "<http://printeps.org/cafe/entrance/c1>" -> "printeps:c1"; "42"^^<…#integer> -> "42"^^xsd:integer. */
export function compact(term) {
  return String(term).replace(/<([^<>\s]+)>/g, (whole, iri) => {
    const hit = PREFIXES.find(([, ns]) => iri.startsWith(ns) && /^[\w.-]*$/.test(iri.slice(ns.length)));
    return hit ? hit[0] + iri.slice(hit[1].length) : whole;
  });
}

function ms(value) {
  if (value === null || value === undefined) return "?";
  return value % 1000 === 0 ? `${value / 1000} s` : `${value} ms`;
}

function shortIri(iri) {
  return String(iri || "").replace(/^.*[/#]/, "") || iri;
}

/** An event time (ms): a clock time for real timestamps, the number itself for small test clocks. */
function eventTime(value) {
  if (typeof value !== "number") return String(value ?? "—");
  if (value < 1e11) return `${value} ms`;
  const date = new Date(value);
  return `${date.toLocaleTimeString()}.${String(value % 1000).padStart(3, "0")}`;
}

// ---------------------------------------------------------------- shared pieces

/** Whether a problem is about the editor's text (the query, the YAML), not another field. */
const inEditor = (p, fields) => !p.field || fields.includes(p.field);

/** A list of problems; each one at a line of the editor's text jumps to it. */
function problemList(problems, view, fields) {
  return h("ul", { class: "problems", "data-testid": "problems" }, problems.map((p) => {
    const here = p.line && inEditor(p, fields);
    const label = !inEditor(p, fields) && !String(p.message).startsWith(`${p.field}:`) ? `${p.field}: ` : "";
    return h("li", {},
      here ? h("button", { class: "link", onclick: () => reveal(view, p), "data-testid": "problem-at" }, `line ${p.line}, column ${p.column}`) : null,
      here ? ": " : "",
      label ? h("b", {}, label) : null,
      p.where && p.where !== "mapping" ? h("code", {}, `${p.where} `) : null,
      p.message);
  }));
}

function errorMessage(prefix, problems, view, fields) {
  return h("div", { class: "message error", role: "alert" }, h("p", {}, prefix), problemList(problems, view, fields));
}

/** The problems of a failed request: its listed errors, or the one it answered with. */
function problemsOf(err) {
  if (err.errors.length) return err.errors;
  const body = err.body && typeof err.body === "object" ? err.body : {};
  return [{ message: err.message, line: body.line || 0, column: body.column || 0, field: body.field, where: body.where }];
}

/** The problems that belong in the editor (the query text / the YAML), as editor diagnostics. */
function markInEditor(view, problems, fields) {
  showProblems(view, problems.filter((p) => p.line && inEditor(p, fields))
    .map((p) => ({ line: p.line, column: p.column, message: p.message, severity: "error" })));
}

function versionsTable(ctx, versions, current, onRollback, onDiff, testid) {
  const rows = versions.slice().sort((a, b) => b.version - a.version);
  return h("table", { class: "versions", "data-testid": testid },
    h("thead", {}, h("tr", {}, ["Version", "Saved", "By", "Comment", ""].map((t) => h("th", { scope: "col" }, t)))),
    h("tbody", {}, rows.map((v) => h("tr", { class: v.version === current ? "live-row" : "", "data-version": v.version },
      h("td", { class: "num" }, String(v.version)), h("td", {}, when(v.deployed_at)), h("td", {}, v.author || "—"),
      h("td", { class: "comment" }, v.comment || ""),
      h("td", {}, v.version === current ? h("span", { class: "badge live" }, "Live now")
        : [diffButton(v.version, onDiff), " ", ctx.isAuthor() ? rollbackButton(v.version, onRollback) : null])))));
}

function diffButton(version, onDiff) {
  return h("button", { class: "secondary", onclick: () => onDiff(version), "data-testid": `diff-${version}` }, "Diff with live");
}

/** The Versions card: the table and, under it, where "Diff with live" shows its comparison. */
function versionsCard(ctx, versions, current, { onRollback, loadText, testid, empty }) {
  const diffEl = h("div", { class: "diff", "aria-live": "polite", "data-testid": "version-diff" });
  const onDiff = (version) => showVersionDiff(diffEl, version, current, loadText);
  return h("div", { class: "card streams-versions" }, h("h2", {}, "Versions"),
    versions.length ? [versionsTable(ctx, versions, current, onRollback, onDiff, testid), diffEl] : h("p", { class: "muted" }, empty));
}

/** A side-by-side line diff of an older version (left) and the live one (right), as History shows
 * rule sets and knowledge (textDiff). */
async function showVersionDiff(diffEl, version, live, loadText) {
  fill(diffEl, h("p", { class: "muted" }, "Loading…"));
  let older;
  let current;
  try {
    [older, current] = await Promise.all([loadText(version), loadText(live)]);
  } catch (err) {
    fill(diffEl, h("div", { class: "message error", role: "alert" }, `Cannot compare: ${err.message}`));
    return;
  }
  if (older === current) {
    fill(diffEl, h("p", {}, `Version ${version} has the same text as the live version ${live}.`));
    return;
  }
  fill(diffEl, h("h3", {}, `Version ${version} (left) → live version ${live} (right)`), textDiff(older, current));
  diffEl.scrollIntoView({ block: "nearest" });
}

/** fn run at most once: a page is disposed by a delete and again when the router leaves it. */
function once(fn) {
  let done = false;
  return () => {
    if (!done) fn();
    done = true;
  };
}

/** Delete, confirmed in place like Roll back: one click asks, the second deletes. */
function deleteButton(what, onDelete) {
  const cell = h("span", { class: "delete-confirm" });
  const idle = () => fill(cell, h("button", { class: "danger", onclick: ask, "data-testid": "delete" }, "Delete"));
  const ask = () => fill(cell, `Delete this ${what}? It stops at once; its versions stay in the catalog. `,
    h("button", { class: "danger", onclick: onDelete, "data-testid": "confirm-delete" }, "Yes, delete"), " ",
    h("button", { class: "secondary", onclick: idle, "data-testid": "cancel-delete" }, "Cancel"));
  idle();
  return cell;
}

/** After a delete: the sidebar without it, and a page that says so (the old page is gone). */
async function showDeleted(main, ctx, what, name) {
  sidebar(ctx, await loadLists(), "", "");
  fill(main, h("section", { class: "streams" },
    h("h1", {}, `${what[0].toUpperCase()}${what.slice(1)} · ${name}`),
    h("div", { class: "message ok", role: "status", "data-testid": "deleted" }, `✓ The ${what} ${name} is deleted.`),
    h("p", {}, h("a", { href: ctx.href("streams") }, "All queries and mappings"))));
}

/** Delete a query or mapping; a refusal (the server's words) shows in the page's message area. */
async function deleteItem(main, ctx, { what, name, path, messageEl, dispose }) {
  try {
    await api("DELETE", path);
  } catch (err) {
    fill(messageEl, h("div", { class: "message error", role: "alert", "data-testid": "delete-error" }, `Not deleted: ${err.message}`));
    return;
  }
  dispose(); // the results refresh and the unsaved-changes warning end with the page
  await showDeleted(main, ctx, what, name);
}

function rollbackButton(version, onRollback) {
  const cell = h("span", { class: "rollback" });
  const idle = () => fill(cell, h("button", { class: "secondary", onclick: ask, "data-testid": `rollback-${version}` }, "Roll back to this version"));
  const ask = () => fill(cell, `Make version ${version} live again? `,
    h("button", { class: "danger", onclick: () => onRollback(version), "data-testid": `confirm-rollback-${version}` }, "Yes, roll back"), " ",
    h("button", { class: "secondary", onclick: idle }, "Cancel"));
  idle();
  return cell;
}

/** An "unsaved changes" badge kept current, and the browser's leave-page warning while it shows. */
function unsavedGuard(isDirty) {
  const badge = h("span", { class: "badge dirty", hidden: true, "data-testid": "unsaved" }, "unsaved changes");
  const warn = (e) => {
    if (!isDirty()) return;
    e.preventDefault();
    e.returnValue = "";
  };
  window.addEventListener("beforeunload", warn);
  return { badge, update: () => { badge.hidden = !isDirty(); }, dispose: () => window.removeEventListener("beforeunload", warn) };
}

function conflictText(what, err, base) {
  const current = err.body && err.body.current;
  return `Not saved: someone saved version ${current ?? "?"} of this ${what} while you were editing (you started from version ${base}). Your text is kept here; reload the page to see theirs.`;
}

// ---------------------------------------------------------------- a continuous query

/** A query's info, its current definition and versions; a template for a new one (name null). */
async function loadQuery(name) {
  if (name === null) return { info: { version: null, windows: [] }, definition: { text: NEW_QUERY, binding: null, report: null, params: null }, versions: [] };
  const info = await api("GET", queryPath(name));
  if (!info.version) return { info, definition: { text: info.text, binding: info.binding, report: null, params: null }, versions: [] };
  const [definition, versions] = await Promise.all([api("GET", queryPath(name, `/versions/${info.version}`)),
    api("GET", queryPath(name, "/versions"))]);
  return { info, definition, versions };
}

async function showQuery(main, ctx, name) {
  if (name === null && !ctx.isAuthor()) return onlyAuthors(main, ctx, "queries");
  fill(main, h("p", { class: "muted" }, name === null ? "Opening a new query…" : `Loading query ${name}…`));
  let info;
  let definition;
  let versions;
  try {
    ({ info, definition, versions } = await loadQuery(name));
  } catch (err) {
    fill(main, h("div", { class: "message error", role: "alert" }, `Cannot open query “${name}”: ${err.message}`),
      h("a", { href: ctx.href("streams") }, "All queries and mappings"));
    return null;
  }
  const author = ctx.isAuthor();
  const messageEl = h("div", { "aria-live": "polite", "data-testid": "query-message" });
  const editorHost = h("div", { class: "editor-host streams-editor", "data-testid": "query-editor" });
  const bindingHost = h("div", { class: "editor-host streams-binding", "data-testid": "binding-editor" });
  const report = h("input", { id: "query-report", class: "text-input", value: definition.report || "", readonly: !author,
    placeholder: "as the query says (REPORT clause), else on window close", "data-testid": "query-report" });
  const comment = h("input", { id: "query-comment", class: "text-input", placeholder: "what did you change?", "data-testid": "query-comment" });
  const resultsEl = h("div", { class: "results", "aria-live": "off", "data-testid": "query-results" });
  const initialBinding = definition.binding ? JSON.stringify(definition.binding, null, 2) : "";
  const guard = unsavedGuard(() => view.state.doc.toString() !== definition.text
    || bindingView.state.doc.toString() !== initialBinding || report.value !== (definition.report || ""));
  const view = createEditor(editorHost, { doc: definition.text, fileName: `${name || "new"}.rq`, readOnly: !author,
    label: "C-SPARQL query text", onChange: () => guard.update() });
  const bindingView = createEditor(bindingHost, { doc: initialBinding, fileName: "binding.json", readOnly: !author,
    label: "Rule binding (JSON)", onChange: () => guard.update() });
  report.addEventListener("input", () => guard.update());
  const state = { base: info.version || 0 };
  let timer = null;
  const dispose = once(() => { clearInterval(timer); guard.dispose(); view.destroy(); bindingView.destroy(); });

  const body = () => {
    const text = bindingView.state.doc.toString().trim();
    let rules = null;
    if (text) {
      try {
        rules = JSON.parse(text);
      } catch (err) {
        return { problem: { field: "rules", message: `the rule binding is not JSON: ${err.message}` } };
      }
    }
    const out = { query: view.state.doc.toString(), rules, report: report.value.trim() || null };
    if (definition.params) out.params = paramsBody(definition.params);
    return { body: out };
  };
  const check = async () => {
    const { body: request, problem } = body();
    if (problem) return showRefused("Not valid:", [problem]);
    fill(messageEl, h("p", { class: "muted" }, "Checking…"));
    let result;
    try {
      result = await api("POST", "/api/queries/validate", request);
    } catch (err) {
      return showRefused("Cannot check:", problemsOf(err));
    }
    if (!result.ok) return showRefused("Not valid:", result.errors);
    markInEditor(view, [], []);
    fill(messageEl, h("div", { class: "message ok", role: "status", "data-testid": "check-ok" },
      `✓ Valid: query ${result.name} — ${describeWindows(result.query.windows)}, reported ${describeReport(result.query.report)}`,
      result.query.fast_path ? ", fast path" : "", ". ",
      result.name === name ? "Save makes it a new version." : result.exists
        ? `A query named ${result.name} already exists: open it to change it.`
        : name === null ? `Save registers it as query ${result.name}.` : `Save registers it as a new query ${result.name} (this one stays).`));
    return result;
  };
  const showRefused = (prefix, problems) => {
    markInEditor(view, problems, ["query"]);
    fill(messageEl, errorMessage(prefix, problems, view, ["query"]));
    return null;
  };
  const save = async () => {
    const checked = await check();
    if (!checked) return;
    const copy = checked.name !== name;
    if (copy && checked.exists) return showRefused("Not saved:", [{ message: `a query named ${checked.name} already exists; open it to change it, or choose another name after REGISTER QUERY.` }]);
    const request = { ...body().body, comment: comment.value, replace: !copy, base_version: copy ? 0 : state.base };
    fill(messageEl, h("p", { class: "muted" }, "Saving…"));
    try {
      const saved = await api("POST", "/api/queries", request);
      ctx.flash("ok", `✓ Query ${saved.name} saved: version ${saved.version} is live.`);
      window.scrollTo(0, 0);
      ctx.navigate(queryHref(ctx, saved.name), true);
    } catch (err) {
      if (err.status === 409 && err.body && err.body.current !== undefined) {
        fill(messageEl, h("div", { class: "message error", role: "alert", "data-testid": "conflict" }, conflictText("query", err, state.base)));
        return;
      }
      showRefused("Not saved (nothing changed on the gateway):", problemsOf(err));
    }
  };
  const rollback = async (version) => {
    try {
      await api("POST", queryPath(name, "/rollback"), { version });
      ctx.flash("ok", `✓ Rolled back: version ${version} of ${name} is live again.`);
      window.scrollTo(0, 0);
      ctx.navigate(queryHref(ctx, name), true);
    } catch (err) {
      fill(messageEl, h("div", { class: "message error", role: "alert" }, `Not rolled back: ${err.message}`));
    }
  };
  view.contentDOM.addEventListener("keydown", (e) => {
    if (author && e.key === "s" && (e.ctrlKey || e.metaKey)) { e.preventDefault(); save(); }
  });

  const fresh = name === null;
  fill(main, h("section", { class: "streams query-page" },
    h("div", { class: "title-row" }, h("h1", {}, fresh ? "New query" : `Query · ${name}`),
      fresh ? null : h("span", { class: "badge live", "data-testid": "query-version" }, info.version ? `version ${info.version} live` : "live, not stored"),
      info.fast_path ? h("span", { class: "badge" }, "fast path") : null, guard.badge,
      // only a stored query can be deleted (the API answers 404 for one registered here only)
      author && info.version ? deleteButton("query", () => deleteItem(main, ctx, { what: "query", name, path: queryPath(name), messageEl, dispose })) : null),
    fresh ? h("p", { class: "hint" }, "Name it after REGISTER QUERY, choose its stream and window, then Check and Save: it runs at once.")
      : h("p", { class: "hint" }, `Windows: ${describeWindows(info.windows)} · reported ${describeReport(info.report)}`,
        info.binding ? ` · feeds rule set ${info.binding.ruleset} as ${info.binding.fact_type} facts` : "",
        info.output_stream ? ` · produces stream <${info.output_stream}>` : ""),
    author ? null : h("p", { class: "message info", "data-testid": "read-only" }, "Read only: sign in as an author to change queries."),
    h("div", { class: "streams-columns" },
      h("div", { class: "streams-main" },
        h("span", { class: "editor-label" }, "C-SPARQL"),
        editorHost,
        h("div", { class: "streams-fields" },
          h("label", { for: "query-report" }, "Report policy (overrides the query's REPORT clause)"), report,
          h("span", { class: "editor-label", id: "binding-label" }, "Rule binding (JSON: ruleset, fact_type, fields…; empty: feeds no rules)"),
          bindingHost,
          author ? [h("label", { for: "query-comment" }, "Comment"), comment] : null),
        messageEl,
        author ? h("div", { class: "buttons" },
          h("button", { class: "secondary", onclick: check, "data-testid": "query-check" }, "Check"),
          h("button", { class: "primary", onclick: save, "data-testid": "query-save" }, "Save")) : null),
      fresh ? null : h("div", { class: "streams-side" },
        h("div", { class: "card" }, h("div", { class: "title-row" }, h("h2", {}, "Latest windows with results"),
          h("button", { class: "secondary", onclick: () => loadResults(name, resultsEl), "data-testid": "results-refresh" }, "Refresh")),
        resultsEl))),
    fresh ? null : versionsCard(ctx, versions, info.version, { onRollback: rollback, testid: "query-versions",
      loadText: async (v) => (await api("GET", queryPath(name, `/versions/${v}`))).text,
      empty: "Registered on this gateway only (not stored): save it to keep it." })));
  if (fresh) return { dispose };
  await loadResults(name, resultsEl);
  timer = setInterval(() => loadResults(name, resultsEl), RESULTS_REFRESH_MS);
  return { dispose };
}

function onlyAuthors(main, ctx, what) {
  fill(main, h("div", { class: "message info", role: "status" }, `Only authors can add ${what}.`),
    h("a", { href: ctx.href("streams") }, "All queries and mappings"));
  return {};
}

/** The stored params ([{name, sparql, value}]) as the registration body takes them. */
function paramsBody(params) {
  return Object.fromEntries(params.map((p) => [p.name, p.sparql !== null && p.sparql !== undefined ? { sparql: p.sparql } : { value: p.value }]));
}

async function loadResults(name, el) {
  if (!el.isConnected && el.childNodes.length) return;
  let data;
  try {
    data = await api("GET", queryPath(name, `/results?nonempty=true&limit=${RESULTS_SHOWN}`));
  } catch (err) {
    fill(el, h("div", { class: "message error" }, err.message));
    return;
  }
  const results = data.results.slice().reverse();
  if (!results.length) {
    fill(el, h("p", { class: "muted", "data-testid": "no-results" }, "No window has had results yet."));
    return;
  }
  const variables = [...new Set(results.flatMap((r) => r.variables || Object.keys((r.rows || [])[0] || {})))];
  fill(el, h("table", { class: "results-table" },
    h("thead", {}, h("tr", {}, ["Window start", "end", ...variables].map((t) => h("th", { scope: "col" }, t)))),
    h("tbody", {}, results.flatMap((r) => (r.rows || []).map((row, i) => h("tr", { class: i ? "" : "first" },
      h("td", {}, i ? "" : eventTime(r.window?.start)), h("td", {}, i ? "" : eventTime(r.window?.end)),
      variables.map((v) => h("td", {}, formatValue(row[v])))))))));
}

function formatValue(value) {
  if (value === null || value === undefined) return "—";
  if (typeof value === "number") return String(Math.round(value * 1000) / 1000);
  return typeof value === "object" ? JSON.stringify(value) : shortIri(value).length < String(value).length && String(value).includes("://") ? shortIri(value) : String(value);
}

// ---------------------------------------------------------------- an RDF mapping

async function showMapping(main, ctx, name, params) {
  if (name === null && !ctx.isAuthor()) return onlyAuthors(main, ctx, "mappings");
  fill(main, h("p", { class: "muted" }, name === null ? "Opening a new mapping…" : `Loading mapping ${name}…`));
  let mapping = { version: null, spec: { subject: "printeps:reading_{id}", fields: { value: "" } }, text: NEW_MAPPING };
  let versions = [];
  try {
    if (name !== null) mapping = await api("GET", mappingPath(name));
    if (mapping.version) versions = await api("GET", mappingPath(name, "/versions"));
  } catch (err) {
    fill(main, h("div", { class: "message error", role: "alert" }, `Cannot open mapping “${name}”: ${err.message}`),
      h("a", { href: ctx.href("streams") }, "All queries and mappings"));
    return null;
  }
  const author = ctx.isAuthor();
  const messageEl = h("div", { "aria-live": "polite", "data-testid": "mapping-message" });
  const editorHost = h("div", { class: "editor-host streams-editor", "data-testid": "mapping-editor" });
  const sampleHost = h("div", { class: "editor-host streams-sample", "data-testid": "sample-editor" });
  const previewEl = h("div", { class: "preview", "aria-live": "polite", "data-testid": "preview" });
  const saveAs = h("input", { id: "mapping-name", class: "text-input", value: name || "", "data-testid": "mapping-name", required: true,
    pattern: "[A-Za-z][A-Za-z0-9_.:\\-]{0,63}" });
  const comment = h("input", { id: "mapping-comment", class: "text-input", placeholder: "what did you change?", "data-testid": "mapping-comment" });
  const guard = unsavedGuard(() => view.state.doc.toString() !== mapping.text);
  const view = createEditor(editorHost, { doc: mapping.text, fileName: `${name || "new"}.yaml`, readOnly: !author,
    label: "Mapping (YAML)", onChange: () => guard.update() });
  const sampleView = createEditor(sampleHost, { doc: JSON.stringify(sampleMessage(mapping.spec), null, 2), fileName: "message.json",
    label: "Sample message (JSON)" });
  const text = () => view.state.doc.toString();
  const dispose = once(() => { guard.dispose(); view.destroy(); sampleView.destroy(); });

  const showRefused = (prefix, problems) => {
    markInEditor(view, problems, ["text"]);
    fill(messageEl, errorMessage(prefix, problems, view, ["text"]));
    return false;
  };
  const validate = async () => {
    fill(messageEl, h("p", { class: "muted" }, "Validating…"));
    let result;
    try {
      result = await api("POST", "/api/mappings/validate", { text: text() });
    } catch (err) {
      return showRefused("Cannot validate:", problemsOf(err));
    }
    if (!result.ok) return showRefused("Not valid:", result.errors);
    markInEditor(view, [], []);
    fill(messageEl, h("div", { class: "message ok", role: "status", "data-testid": "validate-ok" },
      "✓ Valid: every key is known and every predicate is an IRI or a known prefix."));
    return true;
  };
  const save = async () => {
    const target = saveAs.value.trim();
    if (!/^[A-Za-z][A-Za-z0-9_.:-]{0,63}$/.test(target)) {
      return showRefused("Not saved:", [{ message: "the name must start with a letter and hold only letters, digits, _ . : - (at most 64)" }]);
    }
    if (!(await validate())) return; // refused before anything is sent: the text stays, marked
    const copy = target !== name;
    fill(messageEl, h("p", { class: "muted" }, "Saving…"));
    try {
      const saved = await api("PUT", mappingPath(target),
        { text: text(), comment: comment.value, base_version: copy ? 0 : mapping.version || 0 });
      ctx.flash("ok", `✓ Mapping ${saved.name} saved: version ${saved.version} is live.`);
      window.scrollTo(0, 0);
      ctx.navigate(mappingHref(ctx, saved.name), true);
    } catch (err) {
      if (err.status === 409 && err.body && err.body.current !== undefined) {
        const why = copy ? `Not saved: a mapping named ${target} already exists (version ${err.body.current}); open it to change it, or choose another name.`
          : conflictText("mapping", err, mapping.version || 0);
        fill(messageEl, h("div", { class: "message error", role: "alert", "data-testid": "conflict" }, why));
        return;
      }
      showRefused("Not saved (nothing changed on the gateway):", problemsOf(err));
    }
  };
  const preview = async () => {
    let message;
    try {
      message = JSON.parse(sampleView.state.doc.toString());
    } catch (err) {
      fill(previewEl, h("div", { class: "message error", role: "alert" }, `The sample message is not JSON: ${err.message}`));
      return;
    }
    fill(previewEl, h("p", { class: "muted" }, "Mapping…"));
    try {
      const result = await api("POST", mappingPath(name || "draft", "/preview"),
        { message, timestamp: Number(params.get("timestamp")) || 1000, text: text() });
      fill(previewEl, h("p", {}, `${result.triples.length} triples (with the text in the editor; nothing is saved or sent):`),
        h("table", { class: "triples", "data-testid": "triples" },
          h("thead", {}, h("tr", {}, ["Subject", "Predicate", "Object"].map((t) => h("th", { scope: "col" }, t)))),
          h("tbody", {}, result.triples.map((t) => h("tr", {}, t.map((term) => h("td", { title: term }, compact(term))))))));
    } catch (err) {
      const problems = problemsOf(err);
      markInEditor(view, problems, ["text"]);
      fill(previewEl, errorMessage("Cannot map this message:", problems, view, ["text"]));
    }
  };
  const rollback = async (version) => {
    try {
      await api("POST", mappingPath(name, "/rollback"), { version });
      ctx.flash("ok", `✓ Rolled back: version ${version} of mapping ${name} is live again.`);
      window.scrollTo(0, 0);
      ctx.navigate(mappingHref(ctx, name), true);
    } catch (err) {
      fill(messageEl, h("div", { class: "message error", role: "alert" }, `Not rolled back: ${err.message}`));
    }
  };

  fill(main, h("section", { class: "streams mapping-page" },
    h("div", { class: "title-row" }, h("h1", {}, name === null ? "New mapping" : `Mapping · ${name}`),
      name === null ? null : h("span", { class: "badge live", "data-testid": "mapping-version" }, mapping.version ? `version ${mapping.version} live` : "built-in"),
      mapping.spec.message_type ? h("span", { class: "badge" }, mapping.spec.message_type) : null, guard.badge,
      // a built-in mapping has nothing stored to delete (the API answers 404)
      author && mapping.version ? deleteButton("mapping", () => deleteItem(main, ctx, { what: "mapping", name, path: mappingPath(name), messageEl, dispose })) : null),
    h("p", { class: "hint" }, "How one message becomes RDF: subject (an IRI template filled from the message's fields), type, fields → predicates, timed fields (one reading node per message), children (nested lists). Validate and Preview change nothing; Save makes a new version, live at once for every message that arrives."),
    author ? null : h("p", { class: "message info", "data-testid": "read-only" }, "Read only: sign in as an author to change mappings."),
    h("div", { class: "streams-columns" },
      h("div", { class: "streams-main" },
        h("span", { class: "editor-label" }, "Mapping (YAML)"),
        editorHost,
        author ? h("div", { class: "streams-fields" },
          h("label", { for: "mapping-name" }, name === null ? "Name" : "Save as (change the name to save a copy)"), saveAs,
          h("label", { for: "mapping-comment" }, "Comment"), comment) : null,
        messageEl,
        h("div", { class: "buttons" },
          author ? h("button", { class: "secondary", onclick: validate, "data-testid": "mapping-validate" }, "Validate") : null,
          author ? h("button", { class: "primary", onclick: save, "data-testid": "mapping-save" }, "Save") : null)),
      h("div", { class: "streams-side" },
        h("div", { class: "card" }, h("h2", {}, "Preview on a sample message"),
          h("span", { class: "editor-label" }, "Message (JSON)"), sampleHost,
          h("div", { class: "buttons" }, h("button", { class: "secondary", onclick: preview, "data-testid": "mapping-preview" }, "Preview the triples")),
          previewEl))),
    name === null ? null : versionsCard(ctx, versions, mapping.version, { onRollback: rollback, testid: "mapping-versions",
      loadText: async (v) => (await api("GET", mappingPath(name, `/versions/${v}`))).text,
      empty: "Built into the gateway: saving it makes version 1." })));
  view.contentDOM.addEventListener("keydown", (e) => {
    if (author && e.key === "s" && (e.ctrlKey || e.metaKey)) { e.preventDefault(); save(); }
  });
  return { dispose };
}

/** A message the mapping can read: its subject's {placeholders}, fields, timed fields and one
 * element of each child list, with placeholder values to edit. */
export function sampleMessage(spec, depth = 0) {
  const out = {};
  if (!spec || typeof spec !== "object" || depth > 4) return out;
  for (const [, key] of String(spec.subject || "").matchAll(/\{(\w+)\}/g)) out[key] = depth ? `c${depth}` : "1";
  for (const key of Object.keys(spec.fields || {})) if (!(key in out)) out[key] = "value";
  for (const key of Object.keys(spec.timed || {})) out[key] = 1.5;
  for (const [key, child] of Object.entries(spec.children || {})) out[key] = [sampleMessage(child, depth + 1)];
  return out;
}
