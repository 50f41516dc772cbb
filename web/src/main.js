// The workbench shell: one header with the sections (Rules · Workflows · Knowledge · Streams ·
// Live · Dialogue · Decisions · History), a sidebar the current view fills, and one view at a time chosen by the URL
// fragment: #/<section>/<item>?params. Deep links by path (/workbench/workflows/show_to_seat) are
// turned into the same fragment at start, so every item has one shareable address.
//
// A view is a module exporting show(main, ctx, name, params) -> {dispose?} (see SECTIONS); it puts
// its own list in the sidebar with ctx.setSidebar, or leaves the rule set list there.

import "./style.css";
import { h, fill, when } from "./dom.js";
import { api, getToken, setToken } from "./api.js";
import { showRules } from "./rules-view.js";
import { showHistory } from "./history-view.js";
import { showDecisions } from "./decisions-view.js";
import { showWorkflows } from "./workflow-view.js";
import { showKnowledge } from "./knowledge-view.js";
import { showStreams } from "./streams-view.js";
import { showLive } from "./live-view.js";
import { showDialogue } from "./dialogue-view.js";

/** The sections in navigation order: label, view, and whether the rule set list is its sidebar. */
const SECTIONS = [
  { id: "rules", label: "Rules", show: showRules, rulesets: true },
  { id: "workflows", label: "Workflows", show: showWorkflows },
  { id: "knowledge", label: "Knowledge", show: showKnowledge },
  { id: "streams", label: "Streams", show: showStreams },
  { id: "live", label: "Live", show: showLive },
  { id: "dialogue", label: "Dialogue", show: showDialogue },
  { id: "decisions", label: "Decisions", show: showDecisions },
  { id: "history", label: "History", show: showHistory, rulesets: true },
];
const BY_ID = Object.fromEntries(SECTIONS.map((s) => [s.id, s]));

const ctx = {
  user: null,
  rulesets: [],
  view: null,
  /** May change rules (a developer may do all an author may; the server checks an author's rules
   * against the rule policy and answers why a rule is refused, shown like any compile error). */
  isAuthor: () => ctx.user?.role === "author" || ctx.user?.role === "developer",
  /** The fragment of an item: ctx.href("workflows", "show_to_seat") -> "#/workflows/show_to_seat". */
  href: (section, item = "", params = "") =>
    `#/${section}${item ? `/${encodeURIComponent(item)}` : ""}${params ? `?${params}` : ""}`,
  navigate(hash, force = false) {
    if (location.hash === hash && force) route();
    else location.hash = hash;
  },
  /** A message that survives the next navigation (e.g. "rolled back" while the view reloads). */
  flash(kind, text) {
    ctx.pendingFlash = h("div", { class: `message ${kind}`, role: "status" }, text);
    fill(flashEl, ctx.pendingFlash);
  },
  /** Replace the sidebar with a view's own list: a title and the items (nodes). */
  setSidebar(title, items) {
    fill(sideTitleEl, title);
    fill(listEl, items);
    layoutEl.classList.remove("no-sidebar");
  },
  /** Views that need the whole width (Live, Decisions) hide the sidebar. */
  hideSidebar() {
    fill(listEl);
    layoutEl.classList.add("no-sidebar");
  },
  refreshRulesets: () => loadRulesets(),
};

const userEl = h("div", { class: "user", "data-testid": "user" });
const navEl = h("nav", { "aria-label": "Sections" },
  SECTIONS.map((s) => h("a", { href: `#/${s.id}`, dataset: { section: s.id } }, s.label)));
const sideTitleEl = h("h2", { id: "sidebar-title" }, "Rule sets");
const listEl = h("ul", { class: "ruleset-list", "data-testid": "rulesets", "aria-labelledby": "sidebar-title" });
const flashEl = h("div", { class: "flash" });
let mainEl = h("main", { id: "main" });
const contentEl = h("div", { class: "content" }, flashEl, mainEl);
const layoutEl = h("div", { class: "layout" },
  h("aside", { class: "sidebar" }, sideTitleEl, listEl), contentEl);

function shell() {
  fill(document.getElementById("app"),
    h("header", { class: "top" }, h("a", { class: "brand", href: "#/rules" }, "PRINTEPS · Workbench"), navEl, userEl),
    layoutEl);
}

/** /workbench/<section>/<item> (a shared deep link) becomes /workbench#/<section>/<item>. */
function pathToFragment() {
  const rest = location.pathname.replace(/^\/workbench\/?/, "");
  if (!rest) return;
  const [section] = rest.split("/");
  if (!BY_ID[section]) return;
  history.replaceState(null, "", `/workbench#/${rest}${location.search}`);
}

function parseHash() {
  const [path, query = ""] = location.hash.replace(/^#\/?/, "").split("?");
  const [section = "rules", ...rest] = path.split("/");
  let name = "";
  try {
    name = decodeURIComponent(rest.join("/"));
  } catch {
    name = rest.join("/");
  }
  return { section: section || "rules", name, params: new URLSearchParams(query) };
}

/** Counts the routes taken: a view is current while its route is the last one. */
let routeSeq = 0;

/** A fresh <main> for each route, so a view still loading when the user moves on paints into one
 * that is no longer on the page instead of over the next view. */
function freshMain() {
  const main = h("main", { id: "main" });
  contentEl.replaceChild(main, mainEl);
  mainEl = main;
  return main;
}

/** The context one route's view gets: the shell's, except that what changes the page around the
 * view (the sidebar, navigation) does nothing once the user has gone elsewhere. Why: a view that
 * opens its first item after a request (Workflows) used to pull a user who had already clicked
 * on to another section back to it. */
function viewContext(seq) {
  const current = () => seq === routeSeq;
  return Object.assign(Object.create(ctx), {
    setSidebar: (title, items) => { if (current()) ctx.setSidebar(title, items); },
    hideSidebar: () => { if (current()) ctx.hideSidebar(); },
    navigate: (hash, force = false) => { if (current()) ctx.navigate(hash, force); },
    /** Go to `hash` in place of the current address (opening a section's first item). */
    replace: (hash) => { if (current()) location.replace(hash); },
  });
}

async function route() {
  const seq = ++routeSeq;
  const { section, name, params } = parseHash();
  if (ctx.view?.dispose) ctx.view.dispose();
  ctx.view = null;
  const main = freshMain();
  for (const a of navEl.querySelectorAll("a[data-section]")) {
    const active = a.dataset.section === section;
    a.classList.toggle("active", active);
    if (active) a.setAttribute("aria-current", "page");
    else a.removeAttribute("aria-current");
  }
  fill(flashEl, ctx.pendingFlash);
  ctx.pendingFlash = null;
  if (section === "signin" || !ctx.user) return showSignIn();
  const target = BY_ID[section];
  if (!target) {
    fill(mainEl, h("p", { class: "message error", role: "alert" }, `There is no section "${section}". Choose one above.`));
    return;
  }
  document.title = `${target.label} · PRINTEPS workbench`;
  if (target.rulesets) {
    fill(sideTitleEl, "Rule sets");
    layoutEl.classList.remove("no-sidebar");
    renderList();
    if (name) ctx.lastRuleset = name;
    if (!name) return showChooser(section);
  }
  const view = await target.show(main, viewContext(seq), name, params);
  if (seq === routeSeq) ctx.view = view;
  else view?.dispose?.();
}

function showChooser(section) {
  // Stay with the rule set the user was looking at (Rules -> History and back).
  const target = ctx.rulesets.find((r) => r.name === ctx.lastRuleset) || ctx.rulesets[0];
  if (target) {
    location.replace(ctx.href(section === "history" ? "history" : "rules", target.name));
    return;
  }
  fill(mainEl, h("p", { class: "muted" }, "There are no rule sets yet. Put a folder of .drl/.dslr files under rules/drl/ and restart the gateway."));
}

async function loadRulesets() {
  try {
    const data = await api("GET", "/api/rulesets");
    ctx.rulesets = (Array.isArray(data) ? data : data.rulesets || []).slice().sort((a, b) => a.name.localeCompare(b.name));
  } catch (err) {
    ctx.rulesets = [];
    fill(listEl, h("li", { class: "message error" }, err.message));
    return;
  }
  if (BY_ID[parseHash().section]?.rulesets) renderList();
}

function renderList() {
  const { section, name } = parseHash();
  const target = section === "history" ? "history" : "rules";
  fill(listEl, ctx.rulesets.map((r) => h("li", { class: r.name === name ? "active" : "" },
    h("a", { href: ctx.href(target, r.name), "data-ruleset": r.name },
      h("span", { class: "name" }, r.name),
      h("span", { class: "meta" }, `version ${r.version} · ${when(r.deployed_at)}`),
      r.policy === "developer" ? h("span", { class: "meta policy", title: "Deployed by a developer: its rules use Java "
        + "beyond the rule policy. It keeps serving; an author's deploy of such rules is refused." }, "developer rules") : null,
      r.comment ? h("span", { class: "meta comment" }, r.comment) : null))),
  ctx.isAuthor() ? h("li", { class: "new-ruleset" }, newRulesetForm()) : null);
}

const RULESET_NAME = /^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$/;

/** "+ New rule set": a name, then an empty rule set (one starter file) that opens in the editor,
 * ready for sentences, rules or a decision table added from the desktop. */
function newRulesetForm() {
  const nameEl = h("input", { type: "text", "aria-label": "Name of the new rule set", placeholder: "e.g. seat_info",
    "data-testid": "new-ruleset-name", maxlength: "64" });
  const resultEl = h("div", { "aria-live": "polite", "data-testid": "new-ruleset-result" });
  const problem = () => {
    const name = nameEl.value.trim();
    if (!name) return "Give the rule set a name.";
    if (!RULESET_NAME.test(name)) return "A name starts with a letter or digit and holds only letters, digits, '.', '_' and '-' (64 at most).";
    if (ctx.rulesets.some((r) => r.name === name)) return `There is already a rule set named “${name}”.`;
    return "";
  };
  nameEl.addEventListener("input", () => fill(resultEl, nameEl.value && problem() ? h("span", { class: "message error inline" }, problem()) : null));
  const create = async (event) => {
    event.preventDefault();
    const wrong = problem();
    if (wrong) return fill(resultEl, h("span", { class: "message error inline", role: "alert" }, wrong));
    const name = nameEl.value.trim();
    const starter = `package org.printeps.${name.replace(/[^A-Za-z0-9_]/g, "_")};\n\n// The rules of ${name}: write them here, or add .dslr sentences or a decision table (+ Add a file…).\n`;
    try {
      await api("PUT", `/api/rulesets/${encodeURIComponent(name)}`, { files: { [`${name}.drl`]: starter }, comment: "created in the workbench", base_version: 0 });
    } catch (err) {
      return fill(resultEl, h("span", { class: "message error inline", role: "alert" }, `Cannot create “${name}”: ${err.message}`));
    }
    await loadRulesets();
    ctx.navigate(ctx.href("rules", name));
  };
  const formEl = h("form", { class: "new-ruleset-form", hidden: true, onsubmit: create }, nameEl,
    h("button", { class: "primary", type: "submit", "data-testid": "create-ruleset" }, "Create"), resultEl);
  const open = h("button", { class: "link", type: "button", "aria-expanded": "false", onclick: () => {
    formEl.hidden = !formEl.hidden;
    open.setAttribute("aria-expanded", String(!formEl.hidden));
    if (!formEl.hidden) nameEl.focus();
  } }, "+ New rule set");
  return h("div", {}, open, formEl);
}

function renderUser() {
  if (!ctx.user) {
    fill(userEl, h("a", { class: "button secondary", href: "#/signin" }, "Sign in"));
    return;
  }
  const roleHint = {
    developer: "A developer may deploy any rules: DRL is Java code that runs on the gateway.",
    author: "An author may deploy rules within the rule policy: the rule set's own types, its actions, insert/modify/"
      + "update/delete and plain values. A rule that goes beyond it is marked in the editor with the reason.",
    caller: "A caller may look and try; changing rules needs an author or developer token.",
  }[ctx.user.role] || "";
  fill(userEl, h("span", { title: roleHint, "data-testid": "role" }, "Signed in as ", h("b", {}, ctx.user.name || "?"),
    ` (${ctx.user.role})`),
    getToken() ? h("button", { class: "link", onclick: signOut }, "Sign out") : h("a", { class: "link", href: "#/signin" }, "Use a token"));
}

function signOut() {
  setToken("");
  ctx.user = null;
  whoami().then(() => ctx.navigate("#/rules", true));
}

/** Who the stored token (or no token, in open dev mode) belongs to; null when not accepted. */
async function whoami() {
  try {
    ctx.user = await api("GET", "/api/whoami");
  } catch (err) {
    ctx.user = null;
    ctx.whoamiError = err.message;
  }
  renderUser();
  return ctx.user;
}

function showSignIn() {
  fill(listEl);
  const tokenEl = h("input", { type: "password", autocomplete: "current-password", "aria-label": "Access token", placeholder: "paste your token here" });
  const errorEl = h("div", { "aria-live": "polite" });
  const submit = async (event) => {
    event.preventDefault();
    const previous = getToken();
    setToken(tokenEl.value.trim());
    if (await whoami()) {
      await loadRulesets();
      ctx.navigate("#/rules", true);
    } else {
      setToken(previous);
      await whoami();
      fill(errorEl, h("div", { class: "message error", role: "alert" }, "This token was not accepted. Check it and try again."));
    }
  };
  fill(mainEl, h("section", { class: "signin" },
    h("h1", {}, "Sign in"),
    h("p", {}, "Paste the access token you were given. An author token lets you change rules (within the rule policy), workflows and knowledge; a developer token also lets you deploy rules that run any Java code; a caller token lets you look and try."),
    ctx.user ? null : h("p", { class: "muted" }, ctx.whoamiError || ""),
    h("form", { onsubmit: submit }, tokenEl, " ", h("button", { class: "big primary", type: "submit" }, "Sign in")),
    errorEl));
}

async function boot() {
  pathToFragment();
  shell();
  await whoami();
  if (ctx.user) await loadRulesets();
  window.addEventListener("hashchange", route);
  await route();
}

boot();
