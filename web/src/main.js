// The workbench page: header (navigation, who is signed in), the rule set list, and one view at a
// time chosen by the URL fragment: #/rules/NAME, #/history/NAME?from=&to=, #/decisions, #/signin.

import "./style.css";
import { h, fill, when } from "./dom.js";
import { api, getToken, setToken } from "./api.js";
import { showRules } from "./rules-view.js";
import { showHistory } from "./history-view.js";
import { showDecisions } from "./decisions-view.js";

const ctx = {
  user: null,
  rulesets: [],
  view: null,
  isAuthor: () => ctx.user?.role === "author",
  navigate(hash, force = false) {
    if (location.hash === hash && force) route();
    else location.hash = hash;
  },
  /** A message that survives the next navigation (e.g. "rolled back" while the view reloads). */
  flash(kind, text) {
    ctx.pendingFlash = h("div", { class: `message ${kind}`, role: "status" }, text);
    fill(flashEl, ctx.pendingFlash);
  },
  refreshRulesets: () => loadRulesets(),
};

const userEl = h("div", { class: "user", "data-testid": "user" });
const navEl = h("nav", {},
  h("a", { href: "#/rules", dataset: { section: "rules" } }, "Rules"),
  h("a", { href: "#/history", dataset: { section: "history" } }, "History"),
  h("a", { href: "#/decisions", dataset: { section: "decisions" } }, "Recent decisions"),
  h("a", { href: "/workbench/workflows" }, "Workflows"));
const listEl = h("ul", { class: "ruleset-list", "data-testid": "rulesets" });
const flashEl = h("div", { class: "flash" });
const mainEl = h("main", { id: "main" });

function shell() {
  fill(document.getElementById("app"),
    h("header", { class: "top" }, h("a", { class: "brand", href: "#/rules" }, "PRINTEPS · Rules workbench"), navEl, userEl),
    h("div", { class: "layout" },
      h("aside", { class: "sidebar" }, h("h2", {}, "Rule sets"), listEl),
      h("div", { class: "content" }, flashEl, mainEl)));
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

async function route() {
  const { section, name, params } = parseHash();
  if (ctx.view?.dispose) ctx.view.dispose();
  ctx.view = null;
  for (const a of navEl.querySelectorAll("a[data-section]")) a.classList.toggle("active", a.dataset.section === section);
  fill(flashEl, ctx.pendingFlash);
  ctx.pendingFlash = null;
  if (section === "signin" || !ctx.user) return showSignIn();
  renderList();
  if (name) ctx.lastRuleset = name;
  if (section === "decisions") ctx.view = await showDecisions(mainEl, ctx);
  else if (!name) showChooser(section);
  else if (section === "history") ctx.view = await showHistory(mainEl, ctx, name, params);
  else ctx.view = await showRules(mainEl, ctx, name);
}

function showChooser(section) {
  // Stay with the rule set the user was looking at (Rules -> History and back).
  const target = ctx.rulesets.find((r) => r.name === ctx.lastRuleset) || ctx.rulesets[0];
  if (target) {
    location.replace(`#/${section === "history" ? "history" : "rules"}/${encodeURIComponent(target.name)}`);
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
  renderList();
}

function renderList() {
  const { section, name } = parseHash();
  const target = section === "history" ? "history" : "rules";
  fill(listEl, ctx.rulesets.map((r) => h("li", { class: r.name === name ? "active" : "" },
    h("a", { href: `#/${target}/${encodeURIComponent(r.name)}`, "data-ruleset": r.name },
      h("span", { class: "name" }, r.name),
      h("span", { class: "meta" }, `version ${r.version} · ${when(r.deployed_at)}`),
      r.comment ? h("span", { class: "meta comment" }, r.comment) : null))));
}

function renderUser() {
  if (!ctx.user) {
    fill(userEl, h("a", { class: "button secondary", href: "#/signin" }, "Sign in"));
    return;
  }
  fill(userEl, h("span", {}, "Signed in as ", h("b", {}, ctx.user.name || "?"), ` (${ctx.user.role})`),
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
    h("p", {}, "Paste the access token you were given. An author token lets you change and deploy rules; a caller token lets you look and try."),
    ctx.user ? null : h("p", { class: "muted" }, ctx.whoamiError || ""),
    h("form", { onsubmit: submit }, tokenEl, " ", h("button", { class: "big primary", type: "submit" }, "Sign in")),
    errorEl));
}

async function boot() {
  shell();
  await whoami();
  if (ctx.user) await loadRulesets();
  window.addEventListener("hashchange", route);
  await route();
}

boot();
