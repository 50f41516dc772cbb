// Words for owner pages: where a decision came from, and whether a robot is there to act on it —
// said without developer terms (no "REST", no API paths, no process ids).

import { h } from "./dom.js";
import { api } from "./api.js";

/** Where a decision came from, by its recorded origin. */
export const ORIGIN_WORDS = {
  rest: "asked by an app", api: "asked by an app", kie: "asked by a business-rules app",
  stream: "detected by the sensors", ros: "asked by a robot", workflow: "a workflow step",
  cli: "tried from the command line",
};

/**
 * A note on whether robots can act: when the gateway runs without its robot connection, the rules
 * still decide what Pepper would say and do, but nobody performs it — say so, instead of an empty
 * "What the robots did" next to a fired greeting. Resolves to an element, or null when robots are
 * connected (or the gateway cannot tell).
 */
export async function robotStatusNote() {
  let health;
  try {
    health = await api("GET", "/health");
  } catch (err) {
    health = err && err.body; // a degraded gateway answers 503 with the same report
  }
  const ros = health && health.ros;
  if (!ros) return null;
  if (ros.status === "not configured") {
    return h("p", { class: "message info robot-status", "data-testid": "robot-status" },
      "No robot is connected to this gateway, so nothing is performed: the rules still decide what the robots would say and do (shown under Rules fired). ",
      "Start the gateway with its robot connection to see the robots act here.");
  }
  if (ros.status !== "ok") {
    return h("p", { class: "message warning robot-status", "data-testid": "robot-status" },
      `The robot connection is not working (${ros.error || ros.status}): actions may not reach the robots.`);
  }
  return null;
}
