// At tablet width the Deploy and Try cards stack below the editor; this bar keeps them in reach: it
// stays at the bottom of the window and takes the owner to either card with one press. Hidden on
// wide screens, where the cards stand beside the editor (owner.css).

import { h } from "./dom.js";

/** A bar with one button per target: [{label, testid, target: () => element, then?: (el) => void}]. */
export function reachBar(targets) {
  return h("nav", { class: "reach-bar", "aria-label": "Deploy and try" },
    targets.map(({ label, testid, target, then }) => h("button", {
      class: "secondary", "data-testid": testid, onclick: () => {
        const el = target();
        if (!el) return;
        el.scrollIntoView({ block: "start" });
        if (then) then(el);
      },
    }, label)));
}
