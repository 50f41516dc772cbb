// The Tests view: runs the rule set's test scenarios (tests/*.yaml) on the text being edited and
// shows each one green or red, with what was expected against what actually happened, and the rules
// no scenario fires. Failures come first; after an edit the results are marked stale.
// Self-contained: mountTests(host, options) -> {run, markStale, dispose}.

import { h, fill } from "./dom.js";
import { api, rulesetPath } from "./api.js";
import { describeAction } from "./actions.js";

/**
 * Mount the Tests view in `host`.
 * options: name (rule set), files() -> Promise<{name: text}> (the draft to test),
 *          goTo(file, line) (open a scenario's line), onErrors(errors) (compile errors found).
 */
export function mountTests(host, { name, files, goTo = () => {}, onErrors = () => {} }) {
  const summaryEl = h("div", { class: "tests-summary", "data-testid": "tests-summary", "aria-live": "polite" });
  const listEl = h("ol", { class: "tests", "data-testid": "tests" });
  const coverageEl = h("div", { class: "coverage", "data-testid": "coverage" });
  const button = h("button", { class: "big secondary", "data-testid": "run-tests", onclick: () => run() }, "▶ Run the tests");
  fill(host, h("div", { class: "card tests-card" },
    h("h2", {}, "Tests"),
    h("p", { class: "hint" }, "The scenarios in tests/*.yaml say what must keep happening. They run on the text in the editor, and again before every deploy."),
    button, summaryEl, listEl, coverageEl));
  let seq = 0;
  let shown = false;

  /** Run the scenarios; reveal: scroll the results into view once they are in. */
  async function run({ reveal = false } = {}) {
    const mine = ++seq;
    button.disabled = true;
    summaryEl.className = "tests-summary pending";
    summaryEl.textContent = "Running the tests…";
    try {
      const report = await api("POST", rulesetPath(name, "/test"), { files: await files() });
      if (mine === seq) {
        render(report);
        if (reveal) host.scrollIntoView({ block: "start", behavior: "smooth" });
      }
      return report;
    } catch (err) {
      if (mine !== seq) return null;
      summaryEl.className = "tests-summary error";
      summaryEl.textContent = err.errors.length
        ? "The tests cannot run: the rules or a scenario file have problems (see the list under the editor)."
        : `The tests cannot run: ${err.message}`;
      fill(listEl);
      fill(coverageEl);
      if (err.errors.length) onErrors(err.errors);
      return null;
    } finally {
      if (mine === seq) button.disabled = false;
    }
  }

  function render(report) {
    shown = true;
    host.classList.remove("stale");
    const red = report.failed + report.errors;
    if (!report.scenarios) {
      summaryEl.className = "tests-summary muted";
      summaryEl.textContent = "This rule set has no scenarios yet: add a file tests/<name>.yaml.";
    } else if (red) {
      summaryEl.className = "tests-summary error";
      summaryEl.textContent = `✗ ${red} of ${report.scenarios} scenarios fail`;
    } else {
      summaryEl.className = "tests-summary ok";
      summaryEl.textContent = `✓ All ${report.scenarios} scenarios pass`;
    }
    const failedFirst = [...report.results].sort((a, b) => (a.status === "passed") - (b.status === "passed"));
    fill(listEl, failedFirst.map((result) => renderResult(result)));
    const notFired = (report.coverage && report.coverage.not_fired) || [];
    fill(coverageEl, report.scenarios && notFired.length
      ? [h("b", {}, `Rules no scenario fires (${notFired.length} of ${report.coverage.rules}): `), notFired.join(", ")]
      : report.scenarios ? `Every rule (${report.coverage.rules}) is fired by a scenario.` : "");
  }

  function renderResult(result) {
    const passed = result.status === "passed";
    const where = h("button", { class: "link where", onclick: () => goTo(result.file, result.line) }, `${result.file}:${result.line}`);
    if (passed) {
      return h("li", { class: "passed", "data-status": "passed" }, h("span", { class: "mark" }, "✓"), " ", result.name, " ", where);
    }
    return h("li", { class: "failed", "data-status": result.status },
      h("details", { open: true },
        h("summary", {}, h("span", { class: "mark" }, "✗"), " ", result.name, " ", where),
        h("ul", { class: "failures" }, result.failures.map((f) => h("li", {},
          h("button", { class: "link", onclick: () => goTo(result.file, f.line) }, `line ${f.line}`), ": ", f.message))),
        h("div", { class: "compare-cols" },
          h("div", {}, h("h4", {}, "Expected"), renderExpected(result.expected || {})),
          h("div", {}, h("h4", {}, "Actual"), renderActual(result.actual || {})))));
  }

  /** The rules changed since the results shown: say so (they may no longer hold). */
  function markStale() {
    if (!shown || host.classList.contains("stale")) return;
    host.classList.add("stale");
    summaryEl.append(h("span", { class: "stale-note", "data-testid": "tests-stale" },
      " — the rules changed since: run the tests again"));
  }

  return {
    run,
    markStale,
    dispose() {
      seq++;
    },
  };
}

function renderExpected(expect) {
  const parts = [];
  const fired = expect.fired;
  if (fired) {
    const names = Array.isArray(fired) ? fired : Object.entries(fired).map(([n, c]) => `${n} (${c}×)`);
    parts.push(h("p", {}, h("b", {}, "Rules that fire: "), names.join(", ")));
  }
  if (expect.not_fired) parts.push(h("p", {}, h("b", {}, "Rules that must not fire: "), [].concat(expect.not_fired).join(", ")));
  if (expect.actions) {
    parts.push(h("b", {}, expect.ordered ? "Actions, in this order:" : "Actions:"),
      h("ol", {}, expect.actions.map((a) => h("li", {}, describeAction({ module: a.module, params: a.params || {} })))));
  }
  if (expect.no_other_actions) parts.push(h("p", {}, "…and no other action."));
  if (expect.facts) parts.push(h("b", {}, "Facts afterwards:"), h("ul", {}, expect.facts.map((f) => h("li", {}, h("code", {}, JSON.stringify(f))))));
  return parts;
}

function renderActual(actual) {
  if (actual.error) return h("p", { class: "message error" }, actual.error);
  return [
    h("p", {}, h("b", {}, "Rules that fired: "), (actual.fired || []).join(", ") || "none"),
    h("b", {}, "Actions:"),
    (actual.actions || []).length
      ? h("ol", {}, actual.actions.map((a) => h("li", {}, describeAction(a), a.rule ? h("span", { class: "muted" }, ` — ${a.rule}`) : null)))
      : h("p", { class: "muted" }, "none"),
  ];
}
