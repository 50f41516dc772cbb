// The workflow workbench: list, workflow view, scenario view, editor with validation, runs.
// All data comes from /api/workflows (the server computes both views); this file only draws.
"use strict";

const $ = (sel) => document.querySelector(sel);
const SVG = "http://www.w3.org/2000/svg";
let current = null; // {name, version, text, workflow_view, scenario_view}

function headers() {
  const h = { "Content-Type": "application/json" };
  const token = $("#token").value.trim();
  if (token) h.Authorization = "Bearer " + token;
  return h;
}

async function api(method, path, body) {
  const response = await fetch(path, { method, headers: headers(), body: body ? JSON.stringify(body) : undefined });
  const data = await response.json().catch(() => ({}));
  return { status: response.status, data };
}

function el(tag, attrs = {}, text) {
  const node = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, v);
  if (text !== undefined) node.textContent = text;
  return node;
}

function svgRoot(width, height) {
  const svg = el("svg", { width, height, viewBox: `0 0 ${width} ${height}` });
  const defs = el("defs");
  const marker = el("marker", { id: "arrow", viewBox: "0 0 10 10", refX: 10, refY: 5, markerWidth: 6, markerHeight: 6, orient: "auto" });
  marker.appendChild(el("path", { d: "M0,0 L10,5 L0,10 z", fill: "#555" }));
  defs.appendChild(marker);
  svg.appendChild(defs);
  return svg;
}

function box(svg, x, y, w, h, label, cls, id) {
  const g = el("g", { class: "box " + (cls || ""), "data-step": id || "" });
  g.appendChild(el("rect", { x, y, width: w, height: h, rx: 6 }));
  const short = label.length > 26 ? label.slice(0, 25) + "…" : label;
  g.appendChild(el("text", { x: x + 6, y: y + h / 2 + 4 }, short));
  g.appendChild(el("title", {}, label));
  svg.appendChild(g);
}

function edge(svg, x1, y1, x2, y2) {
  svg.appendChild(el("path", { class: "edge", d: `M${x1},${y1} L${x2},${y2}` }));
}

const BW = 170, BH = 30, GAP = 30;

function actorKind(view, actor) {
  const found = (view.actors || []).find((a) => a.name === actor);
  return found ? found.kind : "system";
}

// Steps left to right; a branch puts its "then" and "else" arms in rows below it.
function layoutSteps(svg, view, steps, x, y) {
  let maxY = y + BH;
  let prev = null;
  for (const step of steps) {
    box(svg, x, y, BW, BH, step.label, step.type === "branch" ? "branch" : actorKind(view, step.actor), step.id);
    if (prev) edge(svg, prev, y + BH / 2, x, y + BH / 2);
    if (step.type === "branch") {
      let armY = y + BH + 12;
      for (const [arm, list] of [["then", step.then], ["else", step.otherwise]]) {
        if (!list || !list.length) continue;
        svg.appendChild(el("text", { x: x + 4, y: armY + BH / 2 + 4 }, arm));
        edge(svg, x + 20, y + BH, x + 40, armY);
        const bottom = layoutSteps(svg, view, list, x + 40, armY);
        armY = bottom + 12;
      }
      maxY = Math.max(maxY, armY);
    }
    prev = x + BW;
    x += BW + GAP;
  }
  return maxY;
}

function drawWorkflow(target, view) {
  target.innerHTML = "";
  const svg = svgRoot(1600, 2000);
  let x = 10, y = 10;
  const route = [view.start, ...view.services.map((s) => "service " + s.name), view.end];
  route.forEach((label, i) => {
    box(svg, x, y, BW, BH, label, i === 0 || i === route.length - 1 ? "system" : "");
    if (i) edge(svg, x - GAP, y + BH / 2, x, y + BH / 2);
    x += BW + GAP;
  });
  y += BH + 25;
  for (const service of view.services) {
    for (const name of service.processes) {
      svg.appendChild(el("text", { class: "heading", x: 10, y: y + 12 }, `process ${name} (${service.name})`));
      y = layoutSteps(svg, view, view.processes[name].steps, 10, y + 20) + 25;
    }
  }
  svg.setAttribute("height", y);
  svg.setAttribute("viewBox", `0 0 1600 ${y}`);
  target.appendChild(svg);
}

function drawScenario(target, view) {
  target.innerHTML = "";
  const laneH = BH + 24, left = 130, colW = BW + 20;
  const width = left + Math.max(1, view.steps.length) * colW + 20;
  const height = view.lanes.length * laneH + 20;
  const svg = svgRoot(width, height);
  view.lanes.forEach((lane, i) => {
    svg.appendChild(el("rect", { class: "lane", x: 0, y: 10 + i * laneH, width, height: laneH }));
    svg.appendChild(el("text", { class: "heading", x: 8, y: 10 + i * laneH + laneH / 2 + 4 }, view.labels[lane] || lane));
  });
  let prev = null;
  view.steps.forEach((step, i) => {
    const lane = Math.max(0, view.lanes.indexOf(step.actor));
    const x = left + i * colW, y = 10 + lane * laneH + 12;
    const label = (step.branch ? "[" + step.branch.split(": ")[1] + "] " : "") + step.label;
    box(svg, x, y, BW, BH, label, step.kind === "branch" ? "branch" : (view.kinds || {})[step.actor] || "system", step.id);
    if (prev) edge(svg, prev.x + BW, prev.y + BH / 2, x, y + BH / 2);
    prev = { x, y };
  });
  target.appendChild(svg);
}

function showTab(name) {
  document.querySelectorAll("[role=tab]").forEach((b) => b.setAttribute("aria-selected", String(b.dataset.tab === name)));
  document.querySelectorAll(".tab").forEach((t) => { t.hidden = t.id !== "tab-" + name; });
}

async function loadList() {
  const { status, data } = await api("GET", "/api/workflows");
  const list = $("#list");
  list.innerHTML = "";
  if (status !== 200) { list.textContent = data.error || "cannot list workflows"; return; }
  data.sort((a, b) => (a.business_process || 99) - (b.business_process || 99));
  for (const wf of data) {
    const li = document.createElement("li");
    const button = document.createElement("button");
    button.textContent = (wf.business_process ? wf.business_process + ". " : "") + (wf.title || wf.name);
    button.dataset.name = wf.name;
    button.onclick = () => select(wf.name);
    li.appendChild(button);
    list.appendChild(li);
  }
}

async function select(name) {
  const { status, data } = await api("GET", "/api/workflows/" + encodeURIComponent(name));
  if (status !== 200) { $("#title").textContent = data.error || "not found"; return; }
  current = data;
  document.querySelectorAll("#list button").forEach((b) => b.classList.toggle("current", b.dataset.name === name));
  $("#title").textContent = data.title || data.name;
  $("#meta").textContent = `${data.name} · version ${data.version} · ${data.deployed_at} by ${data.author}` +
    (data.comment ? ` · ${data.comment}` : "");
  drawWorkflow($("#workflow-view"), data.workflow_view);
  drawScenario($("#scenario-view"), data.scenario_view);
  $("#editor").value = data.text;
  $("#problems").innerHTML = "";
  $("#preview").innerHTML = "";
  history.replaceState(null, "", "#" + name);
}

function showProblems(problems) {
  const list = $("#problems");
  list.innerHTML = "";
  for (const p of problems) {
    const li = document.createElement("li");
    li.textContent = `line ${p.line}, column ${p.column}: ${p.path || "(document)"}: ${p.message}`;
    li.onclick = () => goToLine(p.line, p.column);
    list.appendChild(li);
  }
}

function goToLine(line, column) {
  const text = $("#editor").value.split("\n");
  let offset = 0;
  for (let i = 0; i < line - 1 && i < text.length; i++) offset += text[i].length + 1;
  offset += Math.max(0, column - 1);
  $("#editor").focus();
  $("#editor").setSelectionRange(offset, offset);
}

async function validate() {
  const { status, data } = await api("POST", "/api/workflows/validate", { text: $("#editor").value });
  if (status !== 200) { showProblems([{ line: 0, column: 0, path: "", message: data.error || "request failed" }]); return false; }
  if (!data.valid) { showProblems(data.problems); return false; }
  $("#problems").innerHTML = '<li class="ok">valid</li>';
  drawScenario($("#preview"), data.scenario_view);
  return true;
}

async function save() {
  if (!current || !(await validate())) return;
  const body = { text: $("#editor").value, comment: $("#comment").value, base_version: current.version };
  const { status, data } = await api("PUT", "/api/workflows/" + encodeURIComponent(current.name), body);
  if (status === 201) {
    await select(current.name);
    $("#problems").innerHTML = `<li class="ok">version ${data.version} is live</li>`;
  } else if (status === 422) {
    showProblems(data.problems || []);
  } else {
    showProblems([{ line: 0, column: 0, path: "", message: (data.error || "failed") + (data.current ? ` (now version ${data.current})` : "") }]);
  }
}

async function run() {
  if (!current) return;
  let inputs;
  try { inputs = JSON.parse($("#inputs").value || "{}"); } catch (e) { alert("inputs: " + e.message); return; }
  const { data } = await api("POST", "/api/workflows/" + encodeURIComponent(current.name) + "/run", { inputs });
  const body = $("#trace tbody");
  body.innerHTML = "";
  for (const step of data.steps || []) {
    const tr = document.createElement("tr");
    for (const [value, cls] of [[step.step_id], [step.actor || ""], [step.module || step.type],
      [JSON.stringify(step.params)], [step.status + (step.error ? ": " + step.error : ""), step.status]]) {
      const td = document.createElement("td");
      td.textContent = value;
      if (cls) td.className = cls;
      tr.appendChild(td);
    }
    body.appendChild(tr);
  }
}

document.querySelectorAll("[role=tab]").forEach((b) => { b.onclick = () => showTab(b.dataset.tab); });
$("#validate").onclick = validate;
$("#save").onclick = save;
$("#run").onclick = run;
$("#token").value = localStorage.getItem("printeps-token") || "";
$("#token").onchange = () => { localStorage.setItem("printeps-token", $("#token").value); loadList(); };
loadList().then(() => { if (location.hash.length > 1) select(decodeURIComponent(location.hash.slice(1))); });
