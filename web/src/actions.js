// Plain-language rendering of what the rules decided: robot actions and fired rules. Shared by the
// "Try it" panel and the recent-decisions view.

import { h } from "./dom.js";

/** One action ({module, params}) as a sentence a teahouse owner understands. */
export function describeAction(action) {
  const params = (action && action.params) || {};
  const robot = params.robot || "the robot";
  const module = (action && action.module) || "?";
  if (module === "say" && params.text !== undefined) {
    return h("span", { class: "action" }, h("b", {}, robot), " says ", h("q", { class: "speech" }, String(params.text)));
  }
  if (module === "move" && (params.location || params.to)) {
    return h("span", { class: "action" }, h("b", {}, robot), " goes to ", h("b", {}, String(params.location || params.to)));
  }
  if (module === "gesture" && (params.name || params.gesture)) {
    return h("span", { class: "action" }, h("b", {}, robot), " makes the gesture ", h("b", {}, String(params.name || params.gesture)));
  }
  const rest = Object.entries(params).map(([k, v]) => `${k}=${typeof v === "string" ? v : JSON.stringify(v)}`);
  return h("span", { class: "action" }, h("b", {}, module), rest.length ? ` (${rest.join(", ")})` : "");
}

/** The rule name of a "fired" entry (the engine gives {rule, facts}; older records a string). */
export function ruleName(fired) {
  return typeof fired === "string" ? fired : (fired && (fired.rule || fired.name)) || "?";
}

/** The actions list, or a sentence saying there were none. */
export function actionList(actions, emptyText = "Nothing — no rule asked the robot to do anything.") {
  if (!actions || !actions.length) return h("p", { class: "muted" }, emptyText);
  return h("ol", { class: "actions", "data-testid": "actions" }, actions.map((a) => h("li", {}, describeAction(a))));
}

/** The fired rules list, in firing order. */
export function firedList(fired) {
  if (!fired || !fired.length) return h("p", { class: "muted" }, "No rule fired.");
  return h("ol", { class: "fired", "data-testid": "fired" }, fired.map((f) => h("li", {}, ruleName(f))));
}
