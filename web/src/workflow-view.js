// The Workflows section of the workbench (placeholder until its view lands).

import { h, fill } from "./dom.js";

export async function showWorkflows(main, ctx, name) {
  ctx.hideSidebar();
  fill(main, h("section", {}, h("h1", {}, "Workflows"), h("p", { class: "muted" }, "This view is being built.")));
  return {};
}
