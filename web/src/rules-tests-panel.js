// The Rules view's tests panel and what a deploy refused for red scenarios offers: show the tests,
// update them to the draft's sentences, or deploy anyway. Mixed into RulesView (rules-view.js).

import { h, fill } from "./dom.js";
import { setText } from "./editor.js";
import { normalizeErrors } from "./rules-common.js";
import { offerTestUpdate } from "./tests-update.js";
import { mountTests } from "./tests-view.js";

export const testsPanelMethods = {
  // ---- Tests ------------------------------------------------------------------------------------

  buildTests() {
    const host = h("div", { class: "tests-host" });
    this.testsView = mountTests(host, {
      name: this.name,
      files: async () => {
        await this.flushTables();
        return this.files();
      },
      goTo: (file, line) => this.goTo({ file, line, column: 1 }),
      onErrors: (errors) => {
        this.server = normalizeErrors(errors);
        this.renderProblems(false);
      },
    });
    return host;
  },

  /** The deploy was refused because test scenarios are red: say which, offer to update the tests
   * when they only expect words the draft changed, or to deploy anyway. */
  redScenarios(body) {
    const red = ((body.report && body.report.results) || []).filter((r) => r.status !== "passed");
    const updateHost = h("div", { class: "tests-update-host" });
    fill(this.deployResultEl, h("div", { class: "message error", role: "alert", "data-testid": "red-scenarios" },
      h("p", {}, `Not deployed: ${red.length} test scenario${red.length === 1 ? " fails" : "s fail"} with these rules. Nothing was changed.`),
      h("ul", {}, red.map((r) => h("li", {}, h("b", {}, r.name)))),
      updateHost,
      h("details", { class: "red-details" }, h("summary", {}, "What each test expected (details)"),
        h("ul", {}, red.map((r) => h("li", {}, h("b", {}, r.name), ": ", (r.failures[0] && r.failures[0].message) || r.status)))),
      h("p", {}, "Fix the rules (or the scenario, if the change is wanted), or deploy anyway."),
      h("div", { class: "buttons" },
        h("button", { class: "secondary", "data-testid": "show-tests", onclick: () => this.testsView.run({ reveal: true }) }, "Show the tests"),
        h("button", { class: "danger", "data-testid": "deploy-anyway", onclick: () => this.deploy(true) }, "Deploy anyway"))));
    offerTestUpdate(updateHost, { name: this.name, files: this.files(), apply: (files, { allFixed }) => this.updateTests(files, allFixed) });
  },

  /** Put the rewritten test files into their editors; deploy again when nothing else was red. */
  updateTests(files, allFixed) {
    for (const [file, text] of Object.entries(files)) {
      if (this.views[file]) setText(this.views[file], text);
    }
    if (allFixed) this.deploy();
    else this.testsView.run({ reveal: true });
  },
};
