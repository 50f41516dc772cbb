// The workflow palette without duplicates: a module the workflow already has and the palette entry
// it was made from ("say" and "Pepper: say") are one row, named plainly by the entry ("Pepper:
// say"); the entries the workflow has no module for yet are offered under "Add a new module".

/** A module no entry stands for, named plainly: a rule firing by its rule set. */
function plainName(name, module) {
  if (module.kind === "fire_rules" && module.ruleset) return `Fire the ${module.ruleset} rules`;
  return name.replace(/_/g, " ");
}

/**
 * Split the palette for `doc`: `mine` — the workflow's modules, each with the entry it matches
 * (or null) and the plain `label` it is shown with —, and `groups` — the other entries by group.
 * `moduleFor(doc, entry)` says which module of the workflow an entry stands for (or null).
 */
export function paletteRows(doc, entries, moduleFor) {
  const byModule = new Map();
  const rest = [];
  for (const entry of entries || []) {
    const name = moduleFor(doc, entry);
    if (name && !byModule.has(name)) byModule.set(name, entry);
    else if (!name) rest.push(entry);
  }
  const mine = Object.entries(doc.modules || {}).map(([name, module]) => {
    const entry = byModule.get(name) || null;
    return { name, module, entry, label: entry ? entry.label : plainName(name, module) };
  });
  const groups = {};
  for (const entry of rest) (groups[entry.group] = groups[entry.group] || []).push(entry);
  return { mine, groups };
}

/** Module kinds in the owner's words (the badges of the steps and the palette). */
const KIND_WORDS = {
  ros_service: "robot", ros_topic: "message", fire_rules: "rules", ontology_value: "knowledge", wait: "wait",
  manual: "staff", branch: "branch", process: "process", set: "set", module: "module",
};
export const kindWord = (kind) => KIND_WORDS[kind] || String(kind).replace("_", " ");
