// The Knowledge section: the teahouse ontology and its SWRL rules, edited the way an owner thinks of
// them — one value, one rule — never as Turtle. Every save is checked by Pellet on the gateway,
// becomes a new version (History: diff and rollback) and is live at once for the workflows.
//
// Routes: #/knowledge (values) · #/knowledge/<individual> · #/knowledge/values?class=<Class>
//         #/knowledge/rules · #/knowledge/rules/<n> · #/knowledge/history?kind=ontology|swrl

import { h, fill, when, debounce } from "./dom.js";
import { api } from "./api.js";
import { textDiff } from "./editor.js";
import "./knowledge-view.css";
import { NUMBER, kindWords, typeProblem } from "./value-words.js";

const CHECK_AS_YOU_TYPE_MS = 700; // Pellet checks a rule this long after the last keystroke
const SECTIONS = [["values", "Values"], ["rules", "SWRL rules"], ["history", "History"]];

export { typeProblem } from "./value-words.js";

export async function showKnowledge(main, ctx, name, params) {
  const [section, item] = splitName(name);
  sidebar(ctx, section === "individual" ? "" : section, params.get("class") || "", section === "individual" ? item : "");
  if (section === "rules") return showRules(main, ctx, item ? Number(item) : 0);
  if (section === "history") return showHistory(main, ctx, params.get("kind") === "swrl" ? "swrl" : "ontology", params);
  return showValues(main, ctx, section === "individual" ? item : "", params.get("class") || "");
}

function splitName(name) {
  const [first = "", second = ""] = (name || "").split("/");
  if (!first || first === "values") return ["values", ""];
  if (first === "rules" || first === "history") return [first, second];
  return ["individual", first];
}

// ---------------------------------------------------------------- the sidebar: sections and classes

async function sidebar(ctx, section, cls, individual) {
  const items = SECTIONS.map(([id, label]) => h("li", { class: id === section && !cls ? "active" : "" },
    h("a", { href: ctx.href("knowledge", id), "data-section-link": id }, h("span", { class: "name" }, label))));
  ctx.setSidebar("Knowledge", items);
  let tree;
  try {
    tree = (await api("GET", "/api/knowledge/classes")).classes;
  } catch (err) {
    ctx.setSidebar("Knowledge", [...items, h("li", { class: "message error" }, err.message)]);
    return;
  }
  const node = (c) => h("li", {},
    h("a", { href: ctx.href("knowledge", "values", `class=${encodeURIComponent(c.name)}`), class: c.name === cls ? "current" : "",
      "data-class": c.name, title: c.comment || c.label || c.name },
    c.name, c.individuals.length ? h("span", { class: "count" }, ` ${c.individuals.length}`) : null),
    c.individuals.length ? h("ul", { class: "members" }, c.individuals.map((i) => h("li", {},
      h("a", { href: ctx.href("knowledge", i), "data-individual": i, class: i === individual ? "current" : "" }, i)))) : null,
    c.children.length ? h("ul", {}, c.children.map(node)) : null);
  ctx.setSidebar("Knowledge", [...items,
    h("li", { class: "class-tree" }, h("details", { open: !narrow() || Boolean(cls) },
      h("summary", { id: "class-tree-title" }, "Classes"),
      h("ul", { "aria-labelledby": "class-tree-title", "data-testid": "class-tree" }, tree.map(node))))]);
}

/** Tablet width: the class tree starts folded so the page content is in view. */
function narrow() {
  return window.matchMedia("(max-width: 900px)").matches;
}

// ---------------------------------------------------------------- values

async function showValues(main, ctx, individual, cls) {
  fill(main, h("p", { class: "muted" }, "Loading the ontology…"));
  let data;
  let tree;
  try {
    [data, tree] = await Promise.all([api("GET", "/api/knowledge/individuals"), api("GET", "/api/knowledge/classes")]);
  } catch (err) {
    fill(main, h("div", { class: "message error", role: "alert" }, `Cannot load the ontology: ${err.message}`));
    return null;
  }
  if (individual && !data.individuals.some((i) => i.name === individual)) {
    fill(main, h("div", { class: "message error", role: "alert" }, `The ontology has no individual “${individual}”.`),
      h("a", { href: ctx.href("knowledge", "values") }, "Show all values"));
    return null;
  }
  const messageEl = h("div", { "aria-live": "polite", "data-testid": "values-message" });
  const within = cls ? classAndBelow(tree.classes, cls) : null;
  const shown = data.individuals.filter((i) => (!individual || i.name === individual) && (!within || i.types.some((t) => within.has(t))));
  const state = { hash: data.hash, version: data.version };
  const rows = shown.flatMap((ind) => ind.values.map((v) => valueRow(ctx, ind, v, state, messageEl)));
  const title = individual ? `Knowledge · ${individual}` : cls ? `Knowledge · ${cls}` : "Knowledge · Values";
  fill(main, h("section", { class: "knowledge" },
    h("div", { class: "title-row" }, h("h1", {}, title),
      h("span", { class: "badge live", "data-testid": "ontology-version" }, `ontology version ${data.version}`)),
    h("p", { class: "hint" }, "Each value is checked against its type as you type. Save makes it live at once (the workflows read it on their next step); History keeps every version."),
    messageEl,
    rows.length ? h("table", { class: "values", "data-testid": "values" },
      h("thead", {}, h("tr", {}, ["Individual", "Property", "Value", "What it is", ""].map((t) => h("th", { scope: "col" }, t)))),
      h("tbody", {}, rows)) : h("p", { class: "muted" }, "No data values here."),
    individual ? individualCard(ctx, data.individuals.find((i) => i.name === individual)) : null,
    individual && ctx.isAuthor() ? addValueCard(ctx, data, tree.classes, data.individuals.find((i) => i.name === individual), state) : null,
    inferPanel(ctx, data, individual)));
  return {};
}

/** The names of class `cls` and of every class below it in the tree. */
function classAndBelow(tree, cls) {
  const out = new Set();
  const walk = (nodes, inside) => nodes.forEach((c) => {
    const hit = inside || c.name === cls;
    if (hit) out.add(c.name);
    walk(c.children, hit);
  });
  walk(tree, false);
  return out;
}

function valueRow(ctx, ind, v, state, messageEl) {
  const id = `${ind.name}.${v.property}`;
  const row = h("tr", { "data-value": id, class: v.inferred ? "inferred" : "" });
  const nameCell = h("td", {}, h("a", { href: ctx.href("knowledge", ind.name) }, ind.name),
    h("div", { class: "meta" }, ind.types.join(", ")));
  if (v.inferred) {
    fill(row, nameCell, h("td", {}, v.property), h("td", { class: "inferred-value" }, String(v.lexical)),
      h("td", { title: `xsd:${v.datatype}` }, kindWords(v.datatype, v)),
      h("td", {}, h("span", { class: "badge" }, v.rules && v.rules.length
        ? ["inferred by ", v.rules.map((n, i) => [i ? ", " : "", h("a", { href: ctx.href("knowledge", `rules/${n}`) }, `rule ${n}`)])]
        : "inferred")));
    return row;
  }
  const errorId = `err-${id.replace(/\W/g, "-")}`;
  const input = h("input", { class: "value-input", value: v.lexical, "aria-label": `${id} (${kindWords(v.datatype, v)})`,
    inputmode: NUMBER[v.datatype] ? "decimal" : null, "aria-describedby": errorId, "data-testid": `value-${id}` });
  const comment = h("input", { class: "comment-input", placeholder: "why?", "aria-label": `Comment for ${id}` });
  const save = h("button", { class: "primary", disabled: true, "data-testid": `save-${id}` }, "Save");
  const problem = h("div", { id: errorId, class: "field-error", "aria-live": "polite" });
  const readOnly = !ctx.isAuthor();
  let saved = v.lexical;
  const validate = () => {
    const text = typeProblem(v.property, v.datatype, input.value, v);
    fill(problem, text);
    input.setAttribute("aria-invalid", text ? "true" : "false");
    row.classList.toggle("dirty", input.value !== saved);
    save.disabled = readOnly || input.value === saved || Boolean(text);
    return text;
  };
  const submit = async () => {
    const wrong = validate();
    if (wrong) {
      fill(messageEl, h("div", { class: "message error", role: "alert" }, `Not saved: ${wrong}`));
      input.focus();
      return;
    }
    save.disabled = true;
    fill(messageEl, h("div", { class: "message info" }, `Saving ${id}… (Pellet checks the ontology)`));
    try {
      const result = await api("PUT", `/api/knowledge/individuals/${encodeURIComponent(ind.name)}/values/${encodeURIComponent(v.property)}`,
        { value: input.value, comment: comment.value, base_hash: state.hash });
      saved = result.lexical;
      input.value = saved;
      comment.value = "";
      state.version = result.version;
      const fresh = await api("GET", "/api/knowledge/individuals").catch(() => null);
      if (fresh) state.hash = fresh.hash;
      const badge = document.querySelector("[data-testid=ontology-version]");
      if (badge) badge.textContent = `ontology version ${result.version}`;
      fill(messageEl, h("div", { class: "message ok", role: "status" },
        `✓ ${id} = ${result.lexical} is live (ontology version ${result.version}).`));
      validate();
    } catch (err) {
      const field = err.errors[0] || {};
      fill(problem, field.message || err.message);
      input.setAttribute("aria-invalid", "true");
      fill(messageEl, h("div", { class: "message error", role: "alert" }, `Not saved: ${err.message}`));
      save.disabled = false;
    }
  };
  input.addEventListener("input", validate);
  input.addEventListener("keydown", (e) => { if (e.key === "Enter") submit(); if (e.key === "Escape") { input.value = saved; validate(); } });
  save.addEventListener("click", submit);
  fill(row, nameCell, h("td", {}, v.property),
    h("td", {}, input, v.unit ? h("span", { class: "unit", "data-testid": `unit-${id}` }, ` ${v.unit}`) : null, problem),
    h("td", { title: `xsd:${v.datatype}`, "data-testid": `kind-${id}` }, kindWords(v.datatype, v)),
    h("td", { class: "save-cell" }, readOnly ? h("span", { class: "muted" }, "authors can edit") : [comment, " ", save]));
  return row;
}

function individualCard(ctx, ind) {
  return h("div", { class: "card" }, h("h2", {}, ind.name),
    h("p", {}, "Of class ", ind.types.map((t, i) => [i ? ", " : "", h("a", { href: ctx.href("knowledge", "values", `class=${encodeURIComponent(t)}`) }, t)])),
    ind.links.length ? h("ul", { class: "links" }, ind.links.map((l) => h("li", {}, `${l.property} → `,
      h("a", { href: ctx.href("knowledge", l.individual) }, l.individual)))) : null);
}

/** The classes `types` belong to, themselves included (a property whose domain is one of them fits). */
function withAncestors(tree, types) {
  const out = new Set(types);
  const walk = (nodes, path) => nodes.forEach((c) => {
    if (types.includes(c.name)) path.forEach((p) => out.add(p));
    walk(c.children, [...path, c.name]);
  });
  walk(tree, []);
  return out;
}

/** A data value the individual does not have yet: a property that fits its class, a typed value. */
function addValueCard(ctx, data, tree, ind, state) {
  const fits = withAncestors(tree, ind.types);
  const has = new Set(ind.values.map((v) => v.property));
  const props = data.properties.filter((p) => p.kind === "data" && !has.has(p.name) && (!p.domain || fits.has(p.domain)));
  if (!props.length) return null;
  const prop = h("select", { "aria-label": "New property", "data-testid": "add-property" },
    props.map((p) => h("option", { value: p.name }, `${p.name} (${kindWords(p.range || "string", p)})`)));
  const value = h("input", { class: "value-input", "aria-label": "New value", "data-testid": "add-value", "aria-describedby": "add-value-error" });
  const comment = h("input", { class: "comment-input", placeholder: "why?", "aria-label": "Comment for the new value" });
  const problem = h("div", { id: "add-value-error", class: "field-error", "aria-live": "polite" });
  const chosen = () => props.find((p) => p.name === prop.value) || {};
  const range = () => chosen().range || "string";
  const validate = () => {
    const text = value.value ? typeProblem(prop.value, range(), value.value, chosen()) : "";
    fill(problem, text);
    value.setAttribute("aria-invalid", text ? "true" : "false");
    return text || (value.value.trim() ? "" : `${prop.value}: a value is needed`);
  };
  const add = async () => {
    const wrong = validate();
    if (wrong) {
      fill(problem, wrong);
      value.focus();
      return;
    }
    try {
      const result = await api("PUT", `/api/knowledge/individuals/${encodeURIComponent(ind.name)}/values/${encodeURIComponent(prop.value)}`,
        { value: value.value, comment: comment.value, base_hash: state.hash });
      ctx.flash("ok", `✓ ${ind.name}.${result.property} = ${result.lexical} is live (ontology version ${result.version}).`);
      ctx.navigate(ctx.href("knowledge", ind.name), true);
    } catch (err) {
      fill(problem, (err.errors[0] || {}).message || err.message);
    }
  };
  value.addEventListener("input", validate);
  prop.addEventListener("change", validate);
  value.addEventListener("keydown", (e) => { if (e.key === "Enter") add(); });
  return h("div", { class: "card add-value" }, h("h2", {}, `Add a value to ${ind.name}`),
    h("div", { class: "compare" }, prop, " = ", value, " ", comment, " ",
      h("button", { class: "primary", onclick: add, "data-testid": "add-value-button" }, "Add")), problem);
}

// ---------------------------------------------------------------- what does it infer

function inferPanel(ctx, data, individual) {
  const out = h("div", { class: "infer-result", "aria-live": "polite", "data-testid": "infer-result" });
  const select = h("select", { id: "infer-individual", "aria-label": "Individual" },
    data.individuals.map((i) => h("option", { value: i.name, selected: i.name === individual }, i.name)));
  const explain = async () => {
    fill(out, h("p", { class: "muted" }, "Asking Pellet…"));
    try {
      showInferred(ctx, out, await api("GET", `/api/knowledge/individuals/${encodeURIComponent(select.value)}/inferred`));
    } catch (err) {
      fill(out, h("div", { class: "message error", role: "alert" }, err.message));
    }
  };
  const classes = [...new Set(data.properties.map((p) => p.domain).filter(Boolean))].sort();
  const cls = h("select", { "aria-label": "Class of the new individual" }, classes.map((c) => h("option", { value: c, selected: c === "Customer" }, c)));
  const prop = h("select", { "aria-label": "Property" });
  const value = h("input", { "aria-label": "Value", placeholder: "value", size: 8 });
  const fillProps = () => fill(prop, data.properties.filter((p) => p.kind === "data" && (!p.domain || p.domain === cls.value))
    .map((p) => h("option", { value: p.name }, `${p.name} (${kindWords(p.range || "string", p)})`)));
  cls.addEventListener("change", fillProps);
  fillProps();
  const tryIt = async () => {
    const spec = data.properties.find((p) => p.name === prop.value) || {};
    const range = spec.range || "string";
    const problem = value.value.trim() ? typeProblem(prop.value, range, value.value, spec) : "";
    if (problem) {
      fill(out, h("div", { class: "message error", role: "alert" }, problem));
      return;
    }
    const properties = {};
    if (value.value.trim()) properties[prop.value] = NUMBER[range] ? Number(value.value) : range === "boolean" ? value.value === "true" : value.value;
    fill(out, h("p", { class: "muted" }, "Asking Pellet…"));
    try {
      showInferred(ctx, out, await api("POST", "/api/knowledge/try", { individual: { id: "new_individual", types: [cls.value], properties } }));
    } catch (err) {
      fill(out, h("div", { class: "message error", role: "alert" }, err.message));
    }
  };
  const panel = h("div", { class: "card infer", "data-testid": "infer" },
    h("h2", {}, "What does this infer?"),
    h("div", { class: "compare" }, h("label", { for: "infer-individual" }, "For "), select, " ",
      h("button", { class: "secondary", onclick: explain, "data-testid": "infer-button" }, "Show what Pellet infers")),
    h("div", { class: "compare" }, "Or for a new ", cls, " with ", prop, " = ", value, " ",
      h("button", { class: "secondary", onclick: tryIt, "data-testid": "try-button" }, "Try")),
    out);
  if (individual) explain();
  return panel;
}

function showInferred(ctx, out, result) {
  const ruleLinks = (rules) => rules.map((n, i) => [i ? ", " : "", h("a", { href: ctx.href("knowledge", `rules/${n}`) }, `rule ${n}`)]);
  const items = [
    ...result.types.map((t) => h("li", { "data-inferred": `type ${t.class}` }, `is a ${t.class}`,
      h("span", { class: "muted" }, " — ", t.rules.length ? ["by ", ruleLinks(t.rules)] : `because ${t.because}`))),
    ...result.values.map((v) => h("li", { "data-inferred": v.property }, `${v.property} = ${v.lexical}`,
      h("span", { class: "muted" }, " — ", v.rules.length ? ["by ", ruleLinks(v.rules)] : "by the ontology"))),
    ...(result.links || []).map((l) => h("li", {}, `${l.property} → ${l.individual}`,
      h("span", { class: "muted" }, " — ", l.rules.length ? ["by ", ruleLinks(l.rules)] : "by the ontology"))),
  ];
  fill(out, h("p", {}, `Pellet infers for ${result.individual === "new_individual" ? "the new individual" : result.individual}:`),
    items.length ? h("ul", {}, items) : h("p", { class: "muted" }, "nothing beyond what is asserted."));
}

// ---------------------------------------------------------------- SWRL rules

async function showRules(main, ctx, open) {
  fill(main, h("p", { class: "muted" }, "Loading the SWRL rules…"));
  let data;
  try {
    data = await api("GET", "/api/knowledge/swrl/rules");
  } catch (err) {
    fill(main, h("div", { class: "message error", role: "alert" }, `Cannot load the rules: ${err.message}`));
    return null;
  }
  const state = { hash: data.hash, editing: null };
  const messageEl = h("div", { "aria-live": "polite", "data-testid": "rules-message" });
  const list = h("ol", { class: "swrl-rules", "data-testid": "swrl-rules" });
  const render = () => fill(list, data.rules.map((r) => ruleCard(ctx, r, state, messageEl, reload, open)));
  const reload = async (message) => {
    data = await api("GET", "/api/knowledge/swrl/rules");
    state.hash = data.hash;
    state.editing = null;
    render();
    if (message) fill(messageEl, message);
    fill(versionEl, `rules version ${data.version}`);
  };
  const versionEl = h("span", { class: "badge live", "data-testid": "swrl-version" }, `rules version ${data.version}`);
  render();
  fill(main, h("section", { class: "knowledge" },
    h("div", { class: "title-row" }, h("h1", {}, "Knowledge · SWRL rules"), versionEl),
    h("p", { class: "hint" }, "Each rule reads: if everything before “→” holds, Pellet concludes what follows. Edit one rule at a time: Check asks Pellet; Save makes it live as a new version."),
    messageEl, list,
    ctx.isAuthor() ? newRuleCard(ctx, state, messageEl, reload) : null));
  if (open) {
    const card = list.querySelector(`[data-rule="${open}"]`);
    if (card) {
      card.scrollIntoView({ block: "center" });
      card.classList.add("focused");
    }
  }
  return {};
}

function ruleCard(ctx, rule, state, messageEl, reload) {
  const li = h("li", { class: "card rule", "data-rule": rule.number, id: `rule-${rule.number}` });
  const view = () => fill(li,
    h("div", { class: "rule-head" }, h("span", { class: "rule-number" }, `Rule ${rule.number}`),
      rule.comment ? h("span", { class: "rule-comment" }, rule.comment) : null,
      h("span", { class: "muted" }, ` line ${rule.line}`)),
    h("p", { class: "readable", "data-testid": `readable-${rule.number}` }, rule.readable),
    h("code", { class: "rule-text" }, rule.text),
    ctx.isAuthor() ? h("div", { class: "buttons" }, h("button", { class: "secondary", "data-testid": `edit-${rule.number}`,
      onclick: () => {
        if (state.editing && state.editing !== rule.number) {
          fill(messageEl, h("div", { class: "message warning", role: "status" }, `Finish or cancel rule ${state.editing} first.`));
          return;
        }
        state.editing = rule.number;
        edit();
      } }, "Edit")) : null);
  const edit = () => {
    const area = h("textarea", { class: "rule-editor", rows: 3, spellcheck: "false", "aria-label": `Rule ${rule.number} text`,
      "data-testid": `rule-text-${rule.number}` }, );
    area.value = rule.text;
    const comment = h("input", { class: "comment-input", placeholder: "why? (optional)", "aria-label": `Comment for rule ${rule.number}` });
    const verdict = h("div", { class: "verdict", "aria-live": "polite", "data-testid": `verdict-${rule.number}` });
    const typed = debounce(() => runCheck(`/api/knowledge/swrl/rules/${rule.number}/check`, area, verdict), CHECK_AS_YOU_TYPE_MS);
    area.addEventListener("input", typed); // checked as it is typed, as the rule editor checks DRL
    const check = () => { typed.cancel(); return runCheck(`/api/knowledge/swrl/rules/${rule.number}/check`, area, verdict); };
    const save = async () => {
      typed.cancel();
      nextCheck(area); // a check still on its way must not overwrite what the save says
      fill(verdict, h("p", { class: "muted" }, "Pellet is checking and saving…"));
      try {
        const saved = await api("PUT", `/api/knowledge/swrl/rules/${rule.number}`, { text: area.value, comment: comment.value, base_hash: state.hash });
        await reload(h("div", { class: "message ok", role: "status" }, `✓ Rule ${rule.number} saved and live (rules version ${saved.version}).`));
      } catch (err) {
        showVerdict(verdict, false, err.errors.length ? err.errors : [{ message: err.message }], area);
      }
    };
    area.addEventListener("keydown", (e) => {
      if (e.key === "Enter" && (e.ctrlKey || e.metaKey)) { e.preventDefault(); save(); }
    });
    fill(li,
      h("div", { class: "rule-head" }, h("span", { class: "rule-number" }, `Rule ${rule.number}`),
        rule.comment ? h("span", { class: "rule-comment" }, rule.comment) : null),
      h("p", { class: "readable muted" }, rule.readable),
      area, comment, verdict,
      h("div", { class: "buttons" },
        h("button", { class: "secondary", onclick: check, "data-testid": `check-${rule.number}` }, "Check"),
        h("button", { class: "primary", onclick: save, "data-testid": `save-rule-${rule.number}` }, "Save"),
        h("button", { class: "secondary", onclick: () => { state.editing = null; view(); } }, "Cancel")));
    area.focus();
  };
  view();
  return li;
}

function newRuleCard(ctx, state, messageEl, reload) {
  const area = h("textarea", { class: "rule-editor", rows: 2, spellcheck: "false", "aria-label": "New rule text",
    placeholder: "Customer(?c), age(?c, ?a), greaterThan(?a, 64) -> …" });
  const comment = h("input", { class: "comment-input", placeholder: "what the rule is for", "aria-label": "Comment for the new rule" });
  const verdict = h("div", { class: "verdict", "aria-live": "polite" });
  const typed = debounce(() => runCheck("/api/knowledge/swrl/rules/check", area, verdict), CHECK_AS_YOU_TYPE_MS);
  area.addEventListener("input", typed);
  const add = async () => {
    typed.cancel();
    nextCheck(area);
    try {
      const saved = await api("POST", "/api/knowledge/swrl/rules", { text: area.value, comment: comment.value, base_hash: state.hash });
      await reload(h("div", { class: "message ok", role: "status" }, `✓ Rule ${saved.number} added and live (rules version ${saved.version}).`));
    } catch (err) {
      showVerdict(verdict, false, err.errors.length ? err.errors : [{ message: err.message }], area);
    }
  };
  return h("details", { class: "card new-rule" }, h("summary", {}, "Add a rule"), area, comment, verdict,
    h("div", { class: "buttons" },
      h("button", { class: "secondary", onclick: () => { typed.cancel(); runCheck("/api/knowledge/swrl/rules/check", area, verdict); } }, "Check"),
      h("button", { class: "primary", onclick: add }, "Add")));
}

/** A new check (or save) of ``area``: answers to the ones before it are dropped. */
function nextCheck(area) {
  area.dataset.checks = String(Number(area.dataset.checks || 0) + 1);
  return area.dataset.checks;
}

/** Pellet's check of the rule as it is now; an answer to an older text (typing went on) is dropped. */
async function runCheck(path, area, verdict) {
  const seq = nextCheck(area);
  const typing = document.activeElement === area;
  fill(verdict, h("p", { class: "muted" }, "Pellet is checking…"));
  try {
    const result = await api("POST", path, { text: area.value });
    if (area.dataset.checks === seq) showVerdict(verdict, result.ok, result.errors, area, result.changes, !typing);
  } catch (err) {
    if (area.dataset.checks === seq) showVerdict(verdict, false, [{ message: err.message }], area, [], !typing);
  }
}

/** Pellet's verdict: consistent, or each error with where it is (rule, line, column, atom); the
 * cursor goes to the column so the owner sees the spot. */
function showVerdict(verdict, ok, errors, area, changes = [], moveCursor = true) {
  if (ok) {
    fill(verdict, h("div", { class: "message ok", role: "status" }, "✓ Pellet: consistent with the ontology and the other rules.",
      changes.length ? h("ul", { class: "changes", "data-testid": "rule-changes" }, changes.map((c) => h("li", {},
        `${c.value}: ${c.before ?? "—"} → ${c.after ?? "— (no longer inferred)"}`)))
        : h("p", { class: "muted" }, "No inferred value of the ontology's individuals changes (try a new individual under Values).")));
    return;
  }
  fill(verdict, h("div", { class: "message error", role: "alert" }, errors.map((e) => h("p", {},
    h("b", {}, where(e)), e.message))));
  const column = (errors[0] || {}).column;
  if (column && moveCursor) { // not while the owner is typing: the cursor stays where they are
    area.focus();
    area.setSelectionRange(column - 1, Math.min(area.value.length, column - 1 + ((errors[0].atom || "").length || 1)));
  }
}

function where(e) {
  const parts = [e.rule ? `Rule ${e.rule}` : "", e.line ? `line ${e.line}` : "", e.column ? `column ${e.column}` : "",
    e.atom ? `at ${e.atom}` : ""].filter(Boolean);
  return parts.length ? `${parts.join(", ")}: ` : "";
}

// ---------------------------------------------------------------- history

async function showHistory(main, ctx, kind, params) {
  fill(main, h("p", { class: "muted" }, "Loading the history…"));
  let versions;
  let current;
  try {
    [versions, current] = await Promise.all([api("GET", `/api/knowledge/${kind}/versions`), api("GET", `/api/knowledge/${kind}`)]);
  } catch (err) {
    fill(main, h("div", { class: "message error", role: "alert" }, `Cannot load the history: ${err.message}`));
    return null;
  }
  versions = versions.slice().sort((a, b) => b.version - a.version);
  const messageEl = h("div", { "aria-live": "polite", "data-testid": "history-message" });
  const diffEl = h("div", { class: "diff", "data-testid": "diff" });
  const reload = () => ctx.navigate(ctx.href("knowledge", "history", `kind=${kind}`), true);
  const pick = (value, label) => h("select", { "aria-label": label },
    versions.map((v) => h("option", { value: v.version, selected: v.version === value }, `version ${v.version}`)));
  const fromEl = pick(Number(params.get("from")) || (versions[1] || versions[0] || {}).version, "Compare version");
  const toEl = pick(Number(params.get("to")) || (versions[0] || {}).version, "with version");
  const compare = () => showDiff(diffEl, kind, Number(fromEl.value), Number(toEl.value));
  const tabs = h("nav", { class: "kind-tabs", "aria-label": "Which history" }, [["ontology", "Ontology (values)"], ["swrl", "SWRL rules"]].map(([k, label]) =>
    h("a", { href: ctx.href("knowledge", "history", `kind=${k}`), "aria-current": k === kind ? "page" : null, class: k === kind ? "button primary" : "button secondary" }, label)));
  fill(main, h("section", { class: "knowledge history" },
    h("div", { class: "title-row" }, h("h1", {}, "Knowledge · History"), tabs),
    messageEl,
    h("table", { class: "versions", "data-testid": "knowledge-versions" },
      h("thead", {}, h("tr", {}, ["Version", "Saved", "By", "Comment", ""].map((t) => h("th", { scope: "col" }, t)))),
      h("tbody", {}, versions.map((v) => h("tr", { class: v.version === current.version ? "live-row" : "", "data-version": v.version },
        h("td", { class: "num" }, String(v.version)), h("td", {}, when(v.deployed_at)), h("td", {}, v.author || "—"),
        h("td", { class: "comment" }, v.comment || ""),
        h("td", {}, v.version === current.version ? h("span", { class: "badge live" }, "Live now")
          : ctx.isAuthor() ? rollbackButton(kind, v.version, messageEl, ctx, reload) : null))))),
    h("h2", {}, "Compare two versions"),
    h("div", { class: "compare" }, fromEl, " with ", toEl, " ", h("button", { class: "primary", onclick: compare }, "Show differences")),
    diffEl));
  if (versions.length > 1) compare();
  return {};
}

function rollbackButton(kind, version, messageEl, ctx, reload) {
  const cell = h("span", { class: "rollback" });
  const idle = () => fill(cell, h("button", { class: "secondary", onclick: ask, "data-testid": `rollback-${version}` }, "Roll back to this version"));
  const ask = () => fill(cell, `Make version ${version} live again? `,
    h("button", { class: "danger", onclick: go, "data-testid": `confirm-rollback-${version}` }, "Yes, roll back"), " ",
    h("button", { class: "secondary", onclick: idle }, "Cancel"));
  const go = async () => {
    try {
      const result = await api("POST", `/api/knowledge/${kind}/rollback`, { version });
      ctx.flash("ok", `✓ Rolled back: version ${version} is live again (as version ${result.version}).`);
      reload();
    } catch (err) {
      fill(messageEl, h("div", { class: "message error", role: "alert" }, `Not rolled back: ${err.message}`));
    }
  };
  idle();
  return cell;
}

async function showDiff(diffEl, kind, from, to) {
  fill(diffEl, h("p", { class: "muted" }, "Loading…"));
  let a;
  let b;
  try {
    [a, b] = await Promise.all([from, to].map((v) => api("GET", `/api/knowledge/${kind}/versions/${v}`)));
  } catch (err) {
    fill(diffEl, h("div", { class: "message error", role: "alert" }, `Cannot compare: ${err.message}`));
    return;
  }
  if (a.text === b.text) {
    fill(diffEl, h("p", {}, `Versions ${from} and ${to} have the same text.`));
    return;
  }
  fill(diffEl, h("p", {}, `Version ${from} (left) → version ${to} (right):`), textDiff(a.text, b.text));
}
