// Recent decisions: the last N firings of the rules from every origin (REST and KIE clients, the
// stream detectors, ROS, workflows), from the Information State, with the rules that fired and
// what the robot was told to do. Refreshes itself while shown. With an id (#/decisions/<id>, deep
// link /workbench/decisions/<id>, the Live view's links) that one decision is shown on top, whole:
// the facts in, the rules fired, the actions asked and what the robots did.

import "./decisions-view.css";
import { h, fill, when } from "./dom.js";
import { api } from "./api.js";
import { actionList, describeAction, firedList } from "./actions.js";
import { whyCard } from "./why-view.js";
import { ORIGIN_WORDS } from "./owner-words.js";

const REFRESH_MS = 10_000;


const STATUS_WORDS = { ok: "done", failed: "failed", timeout: "timed out", no_service: "robot not reachable", unsupported: "not supported here" };
const FACTS_SHOWN = 50;

export async function showDecisions(main, ctx, name) {
  ctx.hideSidebar();
  const oneEl = h("div", { "data-testid": "decision" });
  const limitEl = h("select", { "aria-label": "How many" }, [20, 50, 200].map((n) => h("option", { value: n, selected: n === 50 }, `last ${n}`)));
  const bodyEl = h("div", { "data-testid": "decisions" });
  const load = async () => {
    try {
      const data = await api("GET", `/api/decisions?limit=${encodeURIComponent(limitEl.value)}`);
      render(bodyEl, Array.isArray(data) ? data : (data && (data.decisions || data.items)) || [], ctx, name);
    } catch (err) {
      fill(bodyEl, h("div", { class: "message error", role: "alert" }, `Cannot load the decisions: ${err.message}`));
    }
  };
  limitEl.addEventListener("change", load);
  fill(main, h("section", { class: "decisions" },
    oneEl,
    h("div", { class: "title-row" }, h(name ? "h2" : "h1", {}, "Recent decisions"), limitEl,
      h("button", { class: "secondary", onclick: load }, "Refresh")),
    h("p", { class: "hint" }, "Each time the rules decided something (a request, a sensor event, a workflow step): which rules fired and what the robot was told to do. Newest first."),
    bodyEl));
  await Promise.all([name ? showOne(oneEl, ctx, name) : null, load()]);
  if (name) oneEl.querySelector("h1")?.focus();
  const timer = setInterval(load, REFRESH_MS);
  return { dispose: () => clearInterval(timer) };
}

/** The decision `id` in full, or a sentence saying why it cannot be shown. */
async function showOne(el, ctx, id) {
  fill(el, h("p", { class: "muted" }, `Loading decision ${id}…`));
  let d;
  try {
    d = await api("GET", `/api/decisions/${encodeURIComponent(id)}`);
  } catch (err) {
    fill(el, h("div", { class: "message error", role: "alert" }, err.status === 404
      ? `There is no decision “${id}”. It may be older than what the Information State keeps, or the link is mistyped.`
      : `Cannot load decision “${id}”: ${err.message}`));
    return;
  }
  const context = d.context || {};
  const facts = d.facts || [];
  const rows = [
    ["When", when(d.at)],
    ["Rule set", d.ruleset ? h("a", { href: ctx.href("rules", d.ruleset) }, `${d.ruleset}${d.version ? ` version ${d.version}` : ""}`) : "—"],
    ["What happened", `${ORIGIN_WORDS[d.origin] || d.origin || "—"}${d.correlation_id ? ` (${d.correlation_id})` : ""}`],
    context.query ? ["Detected by", `${context.query}${context.window ? `, window ${context.window.start}–${context.window.end} ms` : ""}`] : null,
  ].filter(Boolean);
  fill(el, h("section", { class: "card decision-card", "aria-labelledby": "decision-title" },
    h("div", { class: "title-row" }, h("h1", { id: "decision-title", tabindex: "-1" }, "Decision ", h("code", {}, d.decision_id || id)),
      h("a", { class: "button secondary", href: ctx.href("decisions") }, "Close"),
      h("a", { class: "button secondary", href: ctx.href("live") }, "Back to Live")),
    h("dl", {}, rows.map(([k, v]) => [h("dt", {}, k), h("dd", {}, v)])),
    h("h3", {}, "Rules that fired"), firedList(d.fired),
    h("h3", {}, "What the robot was told to do"), actionList(d.actions, "Nothing."),
    h("h3", {}, "What the robots did"), outcomeList(d.outcomes || [], (d.actions || []).length),
    h("h3", {}, `Facts the rules saw (${d.facts_count ?? facts.length})`),
    facts.length ? h("ul", { class: "facts", "data-testid": "facts" }, facts.slice(0, FACTS_SHOWN).map((f) => h("li", {}, factText(f))),
      facts.length > FACTS_SHOWN ? h("li", { class: "muted" }, `and ${facts.length - FACTS_SHOWN} more`) : null)
      : h("p", { class: "muted" }, "No facts."),
    whyCard(d)));
}

function outcomeList(outcomes, asked) {
  if (!outcomes.length) {
    return h("p", { class: "muted" }, asked ? "No outcome recorded (yet): the actions may still be on their way, or this gateway performs no actions for this origin." : "Nothing to do.");
  }
  return h("ol", { class: "outcomes", "data-testid": "outcomes" }, outcomes.map((o) => h("li", {},
    describeAction(o.action || {}), " — ", h("b", {}, STATUS_WORDS[o.status] || o.status || "?"),
    o.message && o.status !== "ok" ? h("span", { class: "muted" }, ` (${o.message})`) : null)));
}

function factText(fact) {
  if (!fact || typeof fact !== "object") return String(fact);
  const { type, ...rest } = fact;
  const shown = (v) => typeof v === "string" ? v : typeof v === "number" && !Number.isInteger(v) ? String(Number(v.toFixed(3))) : JSON.stringify(v);
  const fields = Object.entries(rest).map(([k, v]) => `${k}=${shown(v)}`);
  return [h("b", {}, type || "fact"), fields.length ? ` ${fields.join(", ")}` : ""];
}

function render(bodyEl, decisions, ctx, current) {
  if (!decisions.length) {
    fill(bodyEl, h("p", { class: "muted" }, "No decisions yet."));
    return;
  }
  const sorted = decisions.slice().sort((a, b) => String(timeOf(b)).localeCompare(String(timeOf(a))));
  fill(bodyEl, h("table", { class: "decisions-table" },
    h("thead", {}, h("tr", {}, ["When", "Rule set", "What happened", "Rules that fired", "What the robot did"].map((t) => h("th", {}, t)))),
    h("tbody", {}, sorted.map((d) => h("tr", { class: d.decision_id && d.decision_id === current ? "current-decision" : "" },
      h("td", {}, when(timeOf(d))),
      h("td", {}, `${d.ruleset || "—"}${d.version !== undefined ? ` v${d.version}` : ""}`),
      h("td", { title: d.decision_id || "" },
        d.decision_id ? h("a", { href: ctx.href("decisions", d.decision_id) }, ORIGIN_WORDS[d.origin] || d.origin || "—")
          : ORIGIN_WORDS[d.origin] || d.origin || "—",
        d.correlation_id ? ` (${d.correlation_id})` : ""),
      h("td", {}, firedList(d.fired)),
      h("td", {}, actionList(d.actions, "Nothing.")))))));
}

function timeOf(d) {
  return d.at || d.time || d.timestamp || d.created_at || "";
}
