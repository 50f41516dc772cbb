// The Live section: the teahouse as it happens, from the gateway's live feed (GET /api/live,
// Server-Sent Events). A plot of each person's distance to the entrance over the last minute
// (sensor time), what the stream queries detected, which rules fired (each linked to its
// decision) and what the robots were asked to do with how it went. A window a stream binding
// skipped (its rules still firing an earlier one: gateway/stream/binding_fire.py) is listed with
// the rules and marked on the plot. The fire queues card is a gauge of each rule set's bulkhead
// queue (read from /metrics every few seconds): a queue near its limit means fires are about to be
// refused. Pause freezes the picture (events keep arriving and are shown on resume); leaving the
// view closes the connection.

import "./live-view.css";
import { ORIGIN_WORDS, robotStatusNote } from "./owner-words.js";
import { h, fill } from "./dom.js";
import { api, getToken } from "./api.js";
import { describeAction, ruleName } from "./actions.js";

const WINDOW_MS = 60_000; // the plot shows the last minute of readings
const KEEP_MS = 70_000; // readings kept a little longer, so lines enter from the left edge
const LIST_MAX = 60; // items per event list
const PENDING_MAX = 5000; // events held while paused
const KINDS = ["reading", "detection", "decision", "action", "skipped"];
const COLORS = ["#1f6feb", "#cf222e", "#1a7f37", "#9a6700", "#8250df", "#bf3989", "#0a7ea4", "#57606a"];
const DASHES = ["", "6 3", "2 3", "8 3 2 3"];
const THRESHOLD_REFRESH_MS = 30_000; // the entrance distance is knowledge the owner may change live
const QUEUES_REFRESH_MS = 2_000; // the fire queues gauge: a queue fills and drains in seconds
const STATUS_WORDS = { ok: "done", failed: "failed", timeout: "timed out", no_service: "robot not reachable", unsupported: "not supported here" };

// Plot geometry (SVG user units; the SVG scales to the card's width).
const W = 760, H = 300, M = { left: 56, right: 16, top: 14, bottom: 46 };

const SVG_NS = "http://www.w3.org/2000/svg";

/** An SVG element: s("line", {x1: 0, ...}, children...). */
function s(tag, attrs, ...children) {
  const el = document.createElementNS(SVG_NS, tag);
  for (const [key, value] of Object.entries(attrs || {})) {
    if (value !== null && value !== undefined && value !== "") el.setAttribute(key, String(value));
  }
  for (const child of children.flat()) if (child !== null && child !== undefined) el.append(child);
  return el;
}

/** "http://printeps.org/cafe/entrance/g1a" -> "g1a"; other values as short text. */
function shortValue(value) {
  if (typeof value === "string" && /^(https?:|urn:)/.test(value)) return value.split(/[#/:]/).filter(Boolean).pop();
  if (typeof value === "number") return String(Math.round(value * 100) / 100);
  return typeof value === "string" ? value : JSON.stringify(value);
}

function clock(ms) {
  return new Date(ms).toLocaleTimeString([], { hour12: false });
}

export async function showLive(main, ctx) {
  ctx.hideSidebar();
  const state = {
    series: new Map(), // person -> [{t, d}]
    colors: new Map(), // person -> index in COLORS/DASHES (kept for the whole visit)
    marks: [], // detections on the plot: {t, query}
    skips: [], // windows a binding skipped, on the plot: {t, query, ruleset}
    latest: null, // the newest reading's sensor time (ms): the plot's right edge
    latestAt: null, // when the gateway received it (wall clock, ms): says how current the picture is
    paused: false,
    pending: [],
    skipped: 0,
    lastSeq: new Map(), // feed -> last seq applied (no event is shown twice after a reconnect)
    counts: { reading: 0, detection: 0, decision: 0, action: 0, skipped: 0 },
    process: null,
    drawQueued: false,
    threshold: null, // {name, value}: the ontology's distance to the entrance (the detection threshold)
  };

  const statusEl = h("span", { class: "badge live-status connecting", role: "status", "data-testid": "live-status" }, "Connecting…");
  const pauseBtn = h("button", { class: "secondary", type: "button", "aria-pressed": "false", "data-testid": "pause" }, "Pause");
  const reconnectBtn = h("button", { class: "secondary", type: "button", hidden: true }, "Reconnect");
  const pausedEl = h("span", { class: "muted", "aria-live": "polite", "data-testid": "paused-note" });
  const sourceEl = h("p", { class: "hint" }, "Everything the teahouse's gateway sees, as it happens: people near the entrance, what the sensors' queries detected, the rules that fired and what the robots did.");
  const plotHost = h("div", { class: "live-plot", "data-testid": "live-plot" });
  const legendEl = h("ul", { class: "live-legend", "data-testid": "live-legend", "aria-label": "People and their latest distance" });
  const detectionsEl = h("ol", { class: "live-list", "data-testid": "live-detections", "aria-label": "Detections, newest first" });
  const decisionsEl = h("ol", { class: "live-list", "data-testid": "live-decisions", "aria-label": "Rules fired, newest first" });
  const actionsEl = h("ol", { class: "live-list", "data-testid": "live-actions", "aria-label": "Robot actions, newest first" });
  const empty = (el, text) => fill(el, h("li", { class: "empty muted" }, text));
  empty(detectionsEl, "Nothing detected yet.");
  empty(decisionsEl, "No rules fired yet.");
  empty(actionsEl, "No robot actions yet.");
  const queuesEl = h("ul", { class: "fire-queues", "data-testid": "fire-queues", "aria-label": "Fires waiting, by rule set" });
  empty(queuesEl, "No rule set has fired yet.");
  const robotStatusEl = h("div", { class: "robot-status-host" });

  const card = (title, id, ...body) => h("section", { class: "card live-card", "aria-labelledby": id }, h("h2", { id }, title), ...body);
  fill(main, h("section", { class: "live" },
    h("div", { class: "title-row" }, h("h1", {}, "Live teahouse"), statusEl, pauseBtn, reconnectBtn, pausedEl),
    sourceEl,
    h("div", { class: "live-top" },
      card("Distance to the entrance", "live-plot-title", plotHost, legendEl),
      card("Detected", "live-detections-title", detectionsEl)),
    h("div", { class: "live-bottom" },
      card("Rules fired", "live-decisions-title", decisionsEl),
      card("What the robots did", "live-actions-title", robotStatusEl, actionsEl)),
    card("Fire queues", "live-queues-title",
      h("p", { class: "hint" }, "Fires waiting for each rule set's threads. A full queue refuses new fires (429) until it drains."),
      queuesEl)));
  robotStatusNote().then((note) => { if (note) robotStatusEl.replaceChildren(note); });
  draw();

  // ---- the connection ------------------------------------------------------------------------
  let source = null;
  const setStatus = (kind, text) => {
    statusEl.className = `badge live-status ${kind}`;
    statusEl.textContent = text;
    reconnectBtn.hidden = kind !== "closed";
  };
  const connect = () => {
    if (source) source.close();
    const token = getToken();
    source = new EventSource(`/api/live${token ? `?access_token=${encodeURIComponent(token)}` : ""}`);
    setStatus("connecting", "Connecting…");
    source.addEventListener("open", () => setStatus("open", "● Live"));
    source.addEventListener("error", () => {
      if (source.readyState === EventSource.CLOSED) {
        setStatus("closed", "Not connected. Is the gateway running, and are you signed in?");
      } else {
        setStatus("connecting", "Reconnecting…");
      }
    });
    source.addEventListener("hello", (msg) => {
      const hello = JSON.parse(msg.data);
      state.process = hello.process;
      setStatus("open", "● Live");
      sourceEl.title = hello.process ? `gateway process ${hello.process}` : ""; // for whoever runs it, not in the text
    });
    source.addEventListener("dropped", (msg) => {
      state.skipped += JSON.parse(msg.data).dropped || 0;
      showPaused();
    });
    for (const kind of KINDS) {
      source.addEventListener(kind, (msg) => receive(JSON.parse(msg.data), msg.lastEventId));
    }
  };
  reconnectBtn.addEventListener("click", connect);

  function receive(event, eventId) {
    const feed = (eventId || "").replace(/-\d+$/, "");
    if (feed && event.seq <= (state.lastSeq.get(feed) || 0)) return;
    if (feed) state.lastSeq.set(feed, event.seq);
    if (state.paused) {
      state.pending.push(event);
      if (state.pending.length > PENDING_MAX) {
        state.pending.shift();
        state.skipped += 1;
      }
      showPaused();
      return;
    }
    apply(event);
  }

  pauseBtn.addEventListener("click", () => {
    state.paused = !state.paused;
    pauseBtn.textContent = state.paused ? "Resume" : "Pause";
    pauseBtn.setAttribute("aria-pressed", String(state.paused));
    if (!state.paused) {
      const held = state.pending;
      state.pending = [];
      held.forEach(apply);
    }
    showPaused();
  });

  function showPaused() {
    const parts = [];
    if (state.paused) parts.push(`Paused: ${state.pending.length} new event(s) held, shown when you resume.`);
    if (state.skipped) parts.push(`${state.skipped} event(s) were skipped because this page fell behind.`);
    pausedEl.textContent = parts.join(" ");
  }

  // ---- applying events -------------------------------------------------------------------------
  function apply(event) {
    state.counts[event.kind] += 1;
    if (event.kind === "reading") addReading(event);
    else if (event.kind === "detection") addDetection(event);
    else if (event.kind === "decision") prepend(decisionsEl, decisionItem(event, ctx));
    else if (event.kind === "action") prepend(actionsEl, actionItem(event, ctx));
    else if (event.kind === "skipped") addSkipped(event);
  }

  function addSkipped(event) {
    const end = event.window && event.window.end;
    if (end !== undefined && end !== null) state.skips.push({ t: Number(end), query: event.query, ruleset: event.ruleset });
    prepend(decisionsEl, skippedItem(event));
    scheduleDraw();
  }

  function addReading(event) {
    const t = Number(event.t);
    if (state.latest === null || t >= state.latest) state.latestAt = event.at;
    state.latest = state.latest === null ? t : Math.max(state.latest, t);
    for (const [person, d] of Object.entries(event.distances || {})) {
      if (!state.colors.has(person)) state.colors.set(person, state.colors.size);
      if (!state.series.has(person)) state.series.set(person, []);
      state.series.get(person).push({ t, d: Number(d) });
    }
    scheduleDraw();
  }

  function addDetection(event) {
    const end = event.window && event.window.end;
    if (end !== undefined && end !== null) state.marks.push({ t: Number(end), query: event.query });
    // The same query seeing the same people window after window is one detection going on: its
    // item is updated (latest values, how many windows) instead of a new one each second. "The
    // same people" is any overlap with the query's latest item, since a sliding window may still
    // hold someone who walked past a moment before, or already have lost them.
    const people = detectionPeople(event);
    const latest = [...detectionsEl.querySelectorAll("li.detection")].find((li) => li.dataset.query === (event.query || ""));
    const ongoing = latest && JSON.parse(latest.dataset.people || "[]").some((p) => people.includes(p));
    if (ongoing) {
      const windows = Number(latest.dataset.windows) + 1;
      const item = detectionItem(event, windows, latest.dataset.since);
      item.dataset.people = JSON.stringify(people);
      latest.remove();
      prepend(detectionsEl, item);
    } else {
      const item = detectionItem(event, 1, String(event.at));
      item.dataset.people = JSON.stringify(people);
      prepend(detectionsEl, item);
    }
    scheduleDraw();
  }

  function prepend(list, item) {
    list.querySelector(".empty")?.remove();
    list.prepend(item);
    while (list.children.length > LIST_MAX) list.lastElementChild.remove();
  }

  function scheduleDraw() {
    if (state.drawQueued) return;
    state.drawQueued = true;
    requestAnimationFrame(() => {
      state.drawQueued = false;
      draw();
    });
  }

  // ---- the plot --------------------------------------------------------------------------------
  function draw() {
    const right = state.latest;
    if (right !== null) {
      for (const [person, points] of state.series) {
        while (points.length && points[0].t < right - KEEP_MS) points.shift();
        if (!points.length) state.series.delete(person);
      }
      state.marks = state.marks.filter((m) => m.t >= right - KEEP_MS);
      state.skips = state.skips.filter((m) => m.t >= right - KEEP_MS);
    }
    const people = [...state.series.keys()];
    let maxD = Math.max(5, state.threshold ? state.threshold.value : 0);
    for (const points of state.series.values()) for (const p of points) if (p.t >= right - WINDOW_MS) maxD = Math.max(maxD, p.d);
    const yMax = Math.ceil(maxD);
    const x = (t) => M.left + ((t - (right - WINDOW_MS)) / WINDOW_MS) * (W - M.left - M.right);
    const y = (d) => H - M.bottom - (d / yMax) * (H - M.top - M.bottom);
    const summary = people.length
      ? people.map((p) => `${p} ${last(state.series.get(p)).d.toFixed(1)} m`).join(", ")
      : "nobody seen in the last minute";

    const grid = [];
    for (let sec = 0; sec <= 60; sec += 10) {
      const gx = M.left + ((60 - sec) / 60) * (W - M.left - M.right);
      grid.push(s("line", { x1: gx, x2: gx, y1: M.top, y2: H - M.bottom, class: "grid" }),
        s("text", { x: gx, y: H - M.bottom + 16, class: "tick", "text-anchor": "middle" }, sec ? `−${sec}` : "now"));
    }
    const yStep = yMax > 10 ? 2 : 1;
    for (let d = 0; d <= yMax; d += yStep) {
      grid.push(s("line", { x1: M.left, x2: W - M.right, y1: y(d), y2: y(d), class: "grid" }),
        s("text", { x: M.left - 8, y: y(d) + 4, class: "tick", "text-anchor": "end" }, String(d)));
    }
    const clip = s("clipPath", { id: "live-clip" }, s("rect", { x: M.left, y: M.top, width: W - M.left - M.right, height: H - M.top - M.bottom }));
    const marks = right === null ? [] : state.marks.filter((m) => m.t >= right - WINDOW_MS).map((m) =>
      s("g", { class: "mark" },
        s("line", { x1: x(m.t), x2: x(m.t), y1: M.top, y2: H - M.bottom }),
        s("title", {}, `${m.query} detected something (window ending ${m.t})`)));
    const skips = right === null ? [] : state.skips.filter((m) => m.t >= right - WINDOW_MS).map((m) =>
      s("g", { class: "skip-mark", "data-query": m.query || "" },
        s("line", { x1: x(m.t), x2: x(m.t), y1: M.top, y2: H - M.bottom }),
        s("title", {}, `${m.ruleset} skipped the window of ${m.query} ending ${m.t}: its rules were still firing an earlier one`)));
    const lines = right === null ? [] : people.map((person) => {
      const i = state.colors.get(person);
      const points = state.series.get(person).map((p) => `${x(p.t).toFixed(1)},${y(p.d).toFixed(1)}`).join(" ");
      const end = last(state.series.get(person));
      return s("g", { class: "person", "data-person": person },
        s("polyline", { points, stroke: COLORS[i % COLORS.length], "stroke-dasharray": DASHES[Math.floor(i / COLORS.length) % DASHES.length] }),
        s("circle", { cx: x(end.t), cy: y(end.d), r: 3.5, fill: COLORS[i % COLORS.length] }));
    });
    const svg = s("svg", { viewBox: `0 0 ${W} ${H}`, role: "img", "aria-labelledby": "live-svg-title live-svg-desc", "data-testid": "plot-svg" },
      s("title", { id: "live-svg-title" }, "Each person's distance to the entrance over the last minute"),
      s("desc", { id: "live-svg-desc" }, summary),
      clip, ...grid,
      s("line", { x1: M.left, x2: M.left, y1: M.top, y2: H - M.bottom, class: "axis" }),
      s("line", { x1: M.left, x2: W - M.right, y1: H - M.bottom, y2: H - M.bottom, class: "axis" }),
      state.threshold ? s("g", { class: "threshold", "data-testid": "threshold" },
        s("line", { x1: M.left, x2: W - M.right, y1: y(state.threshold.value), y2: y(state.threshold.value) }),
        s("text", { x: M.left + 6, y: y(state.threshold.value) - 5, "text-anchor": "start" },
          `entrance: ${state.threshold.value} m (${state.threshold.name})`)) : null,
      s("g", { "clip-path": "url(#live-clip)" }, ...marks, ...skips, ...lines),
      s("text", { x: (M.left + W - M.right) / 2, y: H - 8, class: "label", "text-anchor": "middle" }, "seconds before the latest reading (sensor time)"),
      s("text", { x: 14, y: (M.top + H - M.bottom) / 2, class: "label", "text-anchor": "middle",
        transform: `rotate(-90 14 ${(M.top + H - M.bottom) / 2})` }, "distance to the entrance (m)"),
      right === null ? s("text", { x: (M.left + W) / 2, y: H / 2, class: "placeholder", "text-anchor": "middle" },
        "Waiting for readings from the entrance sensor…") : null);
    fill(plotHost, svg, state.latestAt
      ? h("p", { class: "hint live-latest", "data-testid": "latest-reading" }, `Latest entrance reading received at ${clock(state.latestAt)}.`)
      : null);
    fill(legendEl, people.map((person) => {
      const i = state.colors.get(person);
      const swatch = s("svg", { width: 28, height: 10, "aria-hidden": "true" },
        s("line", { x1: 1, x2: 27, y1: 5, y2: 5, stroke: COLORS[i % COLORS.length], "stroke-width": 3,
          "stroke-dasharray": DASHES[Math.floor(i / COLORS.length) % DASHES.length] }));
      return h("li", { "data-person": person }, swatch, " ", h("b", {}, person), ` ${last(state.series.get(person)).d.toFixed(2)} m`);
    }), people.length ? null : h("li", { class: "muted" }, "Nobody near the entrance in the last minute."),
    state.marks.length ? h("li", { class: "mark-key" }, h("span", { class: "mark-swatch", "aria-hidden": "true" }), " a query detected something") : null,
    state.skips.length ? h("li", { class: "mark-key" }, h("span", { class: "skip-swatch", "aria-hidden": "true" }), " a window skipped by busy rules") : null);
  }

  // ---- the fire queues gauge -------------------------------------------------------------------
  const loadQueues = async () => {
    let text;
    try {
      text = await api("GET", "/metrics");
    } catch {
      return; // the gateway is away: the connection status already says so
    }
    if (typeof text !== "string") return;
    const queues = parseQueues(text);
    if (!queues.rulesets.length) return;
    fill(queuesEl, queues.rulesets.map((q) => queueItem(q, queues.limit)));
  };

  const loadThreshold = async () => {
    try {
      const data = await api("GET", "/api/knowledge/values");
      const entry = Object.entries((data && data.values) || {}).find(([key]) => key.endsWith(".distanceToEntrance"));
      const value = entry ? Number(entry[1]) : NaN;
      const next = Number.isFinite(value) ? { name: entry[0], value } : null;
      if (JSON.stringify(next) !== JSON.stringify(state.threshold)) {
        state.threshold = next;
        scheduleDraw();
      }
    } catch {
      // no knowledge base here (or no right to read it): the plot goes without the line
    }
  };
  connect();
  loadThreshold();
  loadQueues();
  const thresholdTimer = setInterval(loadThreshold, THRESHOLD_REFRESH_MS);
  const queuesTimer = setInterval(loadQueues, QUEUES_REFRESH_MS);
  return {
    dispose() {
      clearInterval(thresholdTimer);
      clearInterval(queuesTimer);
      if (source) source.close();
      source = null;
    },
  };
}

function last(points) {
  return points[points.length - 1];
}

function timeCell(event) {
  return h("time", { datetime: new Date(event.at).toISOString() }, clock(event.at));
}

/** What a detection is about: the first column's values (the people, the tables). */
function detectionPeople(event) {
  const rows = event.rows || [];
  const first = (event.variables || (rows[0] ? Object.keys(rows[0]) : []))[0];
  return [...new Set(rows.map((row) => shortValue(row[first])))].sort();
}

function detectionItem(event, windows, since) {
  const rows = event.rows || [];
  const vars = event.variables || (rows[0] ? Object.keys(rows[0]) : []);
  const described = rows.slice(0, 8).map((row) => h("li", {}, vars.filter((v) => row[v] !== undefined && row[v] !== null)
    .map((v, i) => [i ? " · " : "", i ? `${v} ` : "", i ? shortValue(row[v]) : h("b", {}, shortValue(row[v]))])));
  const span = windows > 1 ? ` in ${windows} windows since ${clock(Number(since))}` : "";
  return h("li", { class: "detection", "data-query": event.query || "", dataset: { windows: String(windows), since } },
    h("div", { class: "when-row" }, timeCell(event), " ", h("b", {}, event.query || "a query"),
      ` found ${event.solutions} result${event.solutions === 1 ? "" : "s"}${span}`),
    h("ul", { class: "rows" }, described, rows.length > 8 ? h("li", { class: "muted" }, `and ${rows.length - 8} more`) : null));
}

function decisionItem(event, ctx) {
  const fired = (event.fired || []).map(ruleName);
  return h("li", { class: "decision", "data-decision": event.decision_id || "" },
    h("div", { class: "when-row" }, timeCell(event), " ", h("b", {}, `${event.ruleset || "?"}${event.version ? ` v${event.version}` : ""}`),
      ` — ${ORIGIN_WORDS[event.origin] || event.origin || ""}${event.query ? ` (${event.query})` : ""}`),
    h("div", {}, fired.length ? `Fired: ${fired.join(", ")}` : h("span", { class: "muted" }, "No rule fired.")),
    (event.actions || []).length ? h("ol", { class: "actions" }, event.actions.map((a) => h("li", {}, describeAction(a)))) : null,
    event.decision_id ? h("a", { href: ctx.href("decisions", event.decision_id), class: "decision-link" }, "Open the decision") : null);
}

function actionItem(event, ctx) {
  const status = event.status || "?";
  const kind = status === "ok" ? "ok" : status === "failed" || status === "timeout" ? "error" : "warning";
  const params = event.params || {};
  const action = { module: event.module, params: event.actor && !params.robot ? { ...params, robot: event.actor } : params };
  return h("li", { class: `action-item ${kind}`, "data-status": status },
    h("div", { class: "when-row" }, timeCell(event), " ", describeAction(action), " ",
      h("span", { class: `badge status ${kind}` }, STATUS_WORDS[status] || status)),
    event.message && status !== "ok" ? h("div", { class: "muted small" }, event.message) : null,
    event.source === "workflow"
      ? h("div", { class: "muted small" }, `workflow ${event.workflow || "?"}, step ${event.step || "?"}`)
      : event.decision_id ? h("div", { class: "small" }, "for ", h("a", { href: ctx.href("decisions", event.decision_id) }, "this decision")) : null);
}

function skippedItem(event) {
  const w = event.window || {};
  const span = w.start !== undefined && w.end !== undefined ? `${clock(Number(w.start))}–${clock(Number(w.end))}` : "a window";
  return h("li", { class: "skipped", "data-query": event.query || "", "data-ruleset": event.ruleset || "" },
    h("div", { class: "when-row" }, timeCell(event), " ", h("b", {}, event.ruleset || "?"),
      " skipped ", h("span", { class: "badge status warning" }, "skipped")),
    h("div", {}, `The window ${span} of ${event.query || "a query"} was not decided: its rules were still busy with an earlier window, and a newer window took its place.`),
    event.reason ? h("div", { class: "muted small" }, event.reason) : null);
}

/** The bulkhead gauges of a Prometheus text page: {limit, rulesets: [{name, waiting, running}]},
 * busiest first. Only the lines this view needs are read; label values are unescaped. */
export function parseQueues(text) {
  const byName = new Map();
  let limit = null;
  const line = /^(printeps_fire_queue_depth|printeps_fires_running|printeps_fire_queue_limit)(?:\{ruleset="((?:[^"\\]|\\.)*)"\})?\s+(\S+)/;
  for (const raw of text.split("\n")) {
    const m = line.exec(raw);
    if (!m) continue;
    const value = Number(m[3]);
    if (m[1] === "printeps_fire_queue_limit") {
      limit = value;
      continue;
    }
    const name = (m[2] || "").replace(/\\(.)/g, (_, c) => (c === "n" ? "\n" : c));
    const entry = byName.get(name) || { name, waiting: 0, running: 0 };
    if (m[1] === "printeps_fire_queue_depth") entry.waiting = value;
    else entry.running = value;
    byName.set(name, entry);
  }
  const rulesets = [...byName.values()].sort((a, b) => b.waiting - a.waiting || b.running - a.running || a.name.localeCompare(b.name));
  return { limit, rulesets };
}

function queueItem(q, limit) {
  const full = limit !== null && q.waiting >= limit;
  const kind = full ? "error" : q.waiting > 0 ? "warning" : "ok";
  return h("li", { class: `queue ${kind}`, "data-ruleset": q.name, "data-waiting": String(q.waiting) },
    h("b", {}, q.name), " ",
    h("meter", { min: "0", max: String(limit || Math.max(1, q.waiting)), low: String((limit || 1) / 2), high: String(limit || 1),
      value: String(q.waiting), "aria-label": `${q.name}: fires waiting` }),
    " ", h("span", { class: "queue-words" }, `${q.waiting} waiting${limit !== null ? ` of ${limit}` : ""}, ${q.running} running`),
    full ? h("span", { class: "badge status error" }, "full: new fires are refused") : null);
}
