// Recent decisions: the last N firings of the rules from every origin (REST and KIE clients, the
// stream detectors, ROS, workflows), from the Information State, with the rules that fired and
// what the robot was told to do. Refreshes itself while shown.

import { h, fill, when } from "./dom.js";
import { api } from "./api.js";
import { actionList, firedList } from "./actions.js";

const REFRESH_MS = 10_000;

const ORIGIN_WORDS = {
  rest: "asked over REST", kie: "asked by a KIE client", stream: "detected in the sensor stream",
  ros: "asked by a ROS workflow", workflow: "a workflow step", cli: "the command line",
};

export async function showDecisions(main, ctx) {
  ctx.hideSidebar();
  const limitEl = h("select", { "aria-label": "How many" }, [20, 50, 200].map((n) => h("option", { value: n, selected: n === 50 }, `last ${n}`)));
  const bodyEl = h("div", { "data-testid": "decisions" });
  const load = async () => {
    try {
      const data = await api("GET", `/api/decisions?limit=${encodeURIComponent(limitEl.value)}`);
      render(bodyEl, Array.isArray(data) ? data : (data && (data.decisions || data.items)) || []);
    } catch (err) {
      fill(bodyEl, h("div", { class: "message error", role: "alert" }, `Cannot load the decisions: ${err.message}`));
    }
  };
  limitEl.addEventListener("change", load);
  fill(main, h("section", { class: "decisions" },
    h("div", { class: "title-row" }, h("h1", {}, "Recent decisions"), limitEl,
      h("button", { class: "secondary", onclick: load }, "Refresh")),
    h("p", { class: "hint" }, "Each time the rules decided something (a request, a sensor event, a workflow step), on any gateway process: which rules fired and what the robot was told to do. Newest first."),
    bodyEl));
  await load();
  const timer = setInterval(load, REFRESH_MS);
  return { dispose: () => clearInterval(timer) };
}

function render(bodyEl, decisions) {
  if (!decisions.length) {
    fill(bodyEl, h("p", { class: "muted" }, "No decisions yet."));
    return;
  }
  const sorted = decisions.slice().sort((a, b) => String(timeOf(b)).localeCompare(String(timeOf(a))));
  fill(bodyEl, h("table", { class: "decisions-table" },
    h("thead", {}, h("tr", {}, ["When", "Rule set", "What happened", "Rules that fired", "What the robot did"].map((t) => h("th", {}, t)))),
    h("tbody", {}, sorted.map((d) => h("tr", {},
      h("td", {}, when(timeOf(d))),
      h("td", {}, `${d.ruleset || "—"}${d.version !== undefined ? ` v${d.version}` : ""}`),
      h("td", { title: d.decision_id || "" }, ORIGIN_WORDS[d.origin] || d.origin || "—",
        d.correlation_id ? ` (${d.correlation_id})` : ""),
      h("td", {}, firedList(d.fired)),
      h("td", {}, actionList(d.actions, "Nothing.")))))));
}

function timeOf(d) {
  return d.at || d.time || d.timestamp || d.created_at || "";
}
