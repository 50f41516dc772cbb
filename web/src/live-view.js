// The Live section of the workbench (placeholder until its view lands).

import { h, fill } from "./dom.js";

export async function showLive(main, ctx, name) {
  ctx.hideSidebar();
  fill(main, h("section", {}, h("h1", {}, "Live"), h("p", { class: "muted" }, "This view is being built.")));
  return {};
}
