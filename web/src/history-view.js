// History of a rule set: every version with author, time and comment; the differences between
// any two versions side by side; rollback (author role).

import { h, fill, when } from "./dom.js";
import { api, rulesetPath } from "./api.js";
import { textDiff } from "./editor.js";
import { orderedFiles } from "./rules-view.js";

/** Show the history of rule set `name`; params may hold from/to version numbers to compare. */
export async function showHistory(main, ctx, name, params) {
  fill(main, h("p", { class: "muted" }, `Loading the history of “${name}”…`));
  let versions;
  let current;
  try {
    [versions, current] = await Promise.all([
      api("GET", rulesetPath(name, "/versions")),
      api("GET", rulesetPath(name)),
    ]);
  } catch (err) {
    fill(main, h("div", { class: "message error", role: "alert" }, `Cannot load the history of “${name}”: ${err.message}`));
    return null;
  }
  versions = (Array.isArray(versions) ? versions : versions.versions || []).slice().sort((a, b) => b.version - a.version);
  const live = (current.info || current).version;
  const view = { dispose() {} };
  const messageEl = h("div", { "aria-live": "polite" });
  const diffEl = h("div", { class: "diff", "data-testid": "diff" });

  const reload = () => ctx.navigate(`#/history/${encodeURIComponent(name)}`, true);
  const rows = versions.map((v) => h("tr", { class: v.version === live ? "live-row" : "", "data-version": v.version },
    h("td", { class: "num" }, String(v.version)),
    h("td", {}, when(v.deployed_at)),
    h("td", {}, v.author || "—"),
    h("td", { class: "comment" }, v.comment || ""),
    h("td", {}, v.version === live ? h("span", { class: "badge live" }, "Live now")
      : ctx.isAuthor() ? rollbackButton(name, v.version, messageEl, ctx, reload) : null)));

  const pick = (value) => h("select", {}, versions.map((v) => h("option", { value: v.version, selected: v.version === value }, `version ${v.version}`)));
  const from = Number(params.get("from")) || (versions[1] || versions[0] || {}).version;
  const to = Number(params.get("to")) || (versions[0] || {}).version;
  const fromEl = pick(from);
  const toEl = pick(to);
  const compare = () => showDiff(diffEl, name, Number(fromEl.value), Number(toEl.value));

  fill(main, h("section", { class: "history" },
    h("div", { class: "title-row" }, h("h1", {}, `History of ${name}`),
      h("a", { class: "button secondary", href: `#/rules/${encodeURIComponent(name)}` }, "Open the rules")),
    messageEl,
    h("table", { class: "versions", "data-testid": "versions" },
      h("thead", {}, h("tr", {}, ["Version", "Deployed", "By", "Comment", ""].map((t) => h("th", {}, t)))),
      h("tbody", {}, rows)),
    h("h2", {}, "Compare two versions"),
    h("div", { class: "compare" }, "Compare ", fromEl, " with ", toEl, " ",
      h("button", { class: "primary", onclick: compare }, "Show differences")),
    diffEl));
  if (versions.length > 1 || params.get("from")) compare();
  return view;
}

function rollbackButton(name, version, messageEl, ctx, reload) {
  const cell = h("span", { class: "rollback" });
  const ask = () => fill(cell, `Make version ${version} live again? `,
    h("button", { class: "danger", onclick: () => rollback(name, version, messageEl, ctx, reload) }, "Yes, roll back"), " ",
    h("button", { class: "secondary", onclick: idle }, "Cancel"));
  const idle = () => fill(cell, h("button", { class: "secondary", onclick: ask }, "Roll back to this version"));
  idle();
  return cell;
}

async function rollback(name, version, messageEl, ctx, reload) {
  try {
    const result = await api("POST", rulesetPath(name, "/rollback"), { version });
    const now = result && result.version;
    ctx.flash("ok", now && now !== version
      ? `✓ Rolled back: the rules of version ${version} are live again (as version ${now}).`
      : `✓ Rolled back: version ${version} is live again.`);
    ctx.refreshRulesets();
    reload();
  } catch (err) {
    fill(messageEl, h("div", { class: "message error", role: "alert" }, `Not rolled back: ${err.message}`));
  }
}

async function showDiff(diffEl, name, from, to) {
  fill(diffEl, h("p", { class: "muted" }, "Loading…"));
  let a;
  let b;
  try {
    [a, b] = await Promise.all([from, to].map((v) => api("GET", rulesetPath(name, `/versions/${v}`))));
  } catch (err) {
    fill(diffEl, h("div", { class: "message error", role: "alert" }, `Cannot compare: ${err.message}`));
    return;
  }
  const filesA = await tablesAsText(a.files || {});
  const filesB = await tablesAsText(b.files || {});
  const names = orderedFiles([...new Set([...Object.keys(filesA), ...Object.keys(filesB)])]);
  const changed = names.filter((n) => filesA[n] !== filesB[n]);
  const same = names.filter((n) => filesA[n] === filesB[n]);
  fill(diffEl,
    h("p", {}, changed.length ? `Version ${from} → version ${to}: ${changed.length} file(s) changed.` : `Versions ${from} and ${to} have the same files.`),
    changed.map((n) => {
      const status = !(n in filesA) ? " (added)" : !(n in filesB) ? " (removed)" : "";
      return h("div", { class: "file-diff" }, h("h3", {}, n + status,
        h("span", { class: "muted" }, `  left: version ${from}, right: version ${to}`)),
        textDiff(filesA[n] || "", filesB[n] || "", { fileName: n, margin: 3, minSize: 6 }));
    }),
    same.length ? h("p", { class: "muted" }, `Unchanged: ${same.join(", ")}`) : null);
}

/** Decision tables compared as their rows (cell texts separated by " | "), not as workbook bytes. */
async function tablesAsText(files) {
  const out = { ...files };
  await Promise.all(Object.keys(files).filter((n) => /\.(csv|xlsx)$/i.test(n)).map(async (n) => {
    try {
      out[n] = tableText(await api("POST", "/api/decision-tables/read", { file: n, content: files[n] }));
    } catch {
      out[n] = files[n];
    }
  }));
  return out;
}

function tableText(grid) {
  return grid.sheets.map((sheet) => [`# sheet ${sheet.name}`,
    ...sheet.rows.map((row, i) => `${String(i + 1).padStart(3)} | ${row.join(" | ")}`)].join("\n")).join("\n\n");
}
