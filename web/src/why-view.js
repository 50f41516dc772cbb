// Why, and how long: a recorded decision explained rule by rule in words (GET
// /api/decisions/{id}/explain), and its chain as a timeline (GET /api/traces/{correlation id}),
// for the decision page. Both load on request: the first explanation of a version builds its
// diagnostic queries on the gateway (seconds), later ones take milliseconds.

import { h, fill, when } from "./dom.js";
import { api } from "./api.js";

const KIND_WORDS = {
  sensor_message: "Sensor message", rdf_item: "RDF item", query_result: "Query result",
  decision: "Decision", action: "Robot action",
};

/** A card with "Why these rules?" and, when the decision has a correlation id, "Show the trace". */
export function whyCard(decision) {
  const whyEl = h("div", { "data-testid": "explain" });
  const traceEl = h("div", { "data-testid": "trace" });
  const explainButton = h("button", { class: "secondary", "data-testid": "explain-button" }, "Why these rules? Explain rule by rule");
  explainButton.addEventListener("click", () => loadExplain(whyEl, decision.decision_id, explainButton));
  const traceButton = decision.correlation_id
    ? h("button", { class: "secondary", "data-testid": "trace-button", onclick: () => loadTrace(traceEl, decision.correlation_id) }, "Show the trace")
    : null;
  return h("section", { class: "card why-card", "aria-label": "Why and when" },
    h("h3", {}, "Why"), h("div", { class: "buttons" }, explainButton, traceButton), whyEl, traceEl);
}

async function loadExplain(el, id, button) {
  button.disabled = true;
  fill(el, h("p", { class: "muted", role: "status" }, "Asking the rules… (the first time for a version takes a few seconds)"));
  try {
    const answer = await api("GET", `/api/decisions/${encodeURIComponent(id)}/explain`);
    fill(el, explainList(answer));
  } catch (err) {
    fill(el, h("div", { class: "message error", role: "alert" }, `Cannot explain this decision: ${err.message}`));
  } finally {
    button.disabled = false;
  }
}

/** Every rule in words: fired (with what it matched) or the condition that stopped it. */
export function explainList(answer) {
  const rules = answer.rules || [];
  const fired = rules.filter((r) => r.fired);
  return h("div", {},
    answer.note ? h("p", { class: "hint" }, answer.note) : null,
    h("p", {}, `${fired.length} of ${rules.length} rules fired.`),
    h("ol", { class: "explain-list" }, rules.map((r) => h("li", { class: r.fired ? "fired" : "not-fired", "data-rule": r.rule },
      h("b", {}, r.fired ? "✓ " : "✗ ", r.rule),
      r.fired ? h("span", {}, ` fired${(r.matches || []).length > 1 ? ` ${r.matches.length} times` : ""}.`)
        : h("span", {}, " did not fire: ", stoppedAt(r))))));
}

function stoppedAt(rule) {
  const c = rule.condition;
  if (!c) return rule.reason || "";
  const where = c.cell ? `${c.file}!${c.sheet}!${c.cell}` : `${c.file}:${c.line}`;
  return [
    h("span", { class: "reason" }, rule.reason || ""),
    h("span", { class: "muted" }, ` — condition ${c.index} of ${c.of} (${where}): `),
    h("code", { class: "written" }, c.written || c.drl),
  ];
}

async function loadTrace(el, correlationId) {
  fill(el, h("p", { class: "muted", role: "status" }, "Loading the trace…"));
  try {
    fill(el, timeline(await api("GET", `/api/traces/${encodeURIComponent(correlationId)}`)));
  } catch (err) {
    fill(el, h("div", { class: "message error", role: "alert" }, `Cannot load the trace: ${err.message}`));
  }
}

/** The chain as a timeline: each record, when, and the time since the one before. */
export function timeline(trace) {
  const items = trace.items || [];
  return h("div", {},
    h("p", {}, `${items.length} records, ${Math.round(trace.total_ms || 0)} ms from first to last.`),
    h("ol", { class: "timeline" }, items.map((item) => h("li", { class: `hop-${item.kind}` },
      h("b", {}, KIND_WORDS[item.kind] || item.kind),
      h("span", { class: "muted" }, ` ${when(item.at)}`),
      item.since_previous_ms !== null && item.since_previous_ms !== undefined ? h("span", { class: "hop" }, ` +${item.since_previous_ms} ms`) : null,
      h("span", {}, ` ${summary(item)}`)))));
}

function summary(item) {
  const r = item.record || {};
  if (item.kind === "decision") return `${r.ruleset} v${r.version}: ${(r.fired || []).join(", ") || "no rule fired"}`;
  if (item.kind === "action") return `${(r.action || {}).module || "?"} — ${r.status || "?"}`;
  if (item.kind === "query_result") return `${r.query}: ${r.solutions ?? (r.rows || []).length} solution(s)`;
  if (item.kind === "rdf_item") return `${(r.triples || []).length} triples on ${r.stream}`;
  if (item.kind === "sensor_message") return `from ${r.source}`;
  return "";
}
