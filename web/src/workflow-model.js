// The workflow document as the visual editor changes it: plain data (the parsed YAML), addressed by
// paths such as ["processes", "lead_to_table", "steps", 1] or [..., "steps", 0, "else", 0].
// Why separate from the view: these are the editing rules (where a step is, moving it, giving it a
// unique id, finding or creating the module a palette entry stands for), testable by reading.

/** The value at `path` in `doc` (undefined when any part is missing). */
export function getIn(doc, path) {
  let value = doc;
  for (const key of path) {
    if (value === null || value === undefined) return undefined;
    value = value[key];
  }
  return value;
}

/** The steps array at `listPath`, created (empty) when it is missing (an `else` arm not there yet). */
export function listAt(doc, listPath) {
  const parent = getIn(doc, listPath.slice(0, -1));
  const key = listPath[listPath.length - 1];
  if (!Array.isArray(parent[key])) parent[key] = [];
  return parent[key];
}

/** Remove an `else` arm that became empty (an empty arm is not valid YAML for a workflow). */
function tidyArm(doc, listPath) {
  const key = listPath[listPath.length - 1];
  const parent = getIn(doc, listPath.slice(0, -1));
  if (key === "else" && parent && Array.isArray(parent.else) && parent.else.length === 0) delete parent.else;
}

export function samePath(a, b) {
  return !!a && !!b && a.length === b.length && a.every((x, i) => x === b[i]);
}

/** Every step of the document with its path, depth first (branch arms after their branch). */
export function allSteps(doc) {
  const out = [];
  const walk = (steps, path) => (steps || []).forEach((step, i) => {
    const here = [...path, i];
    out.push({ step, path: here });
    if (step && typeof step === "object") {
      walk(step.then, [...here, "then"]);
      walk(step.else, [...here, "else"]);
    }
  });
  for (const name of Object.keys(doc.processes || {})) walk(doc.processes[name].steps, ["processes", name, "steps"]);
  return out;
}

export function findStep(doc, id) {
  return allSteps(doc).find((s) => s.step && s.step.id === id) || null;
}

/** A step id not used yet: `base`, else base_2, base_3, ... */
export function uniqueStepId(doc, base) {
  const used = new Set(allSteps(doc).map((s) => s.step && s.step.id));
  const clean = String(base || "step").replace(/[^A-Za-z0-9_]/g, "_").replace(/^(?=\d)/, "_");
  if (!used.has(clean)) return clean;
  for (let n = 2; ; n += 1) if (!used.has(`${clean}_${n}`)) return `${clean}_${n}`;
}

export function uniqueModuleName(doc, base) {
  const used = new Set(Object.keys(doc.modules || {}));
  if (!used.has(base)) return base;
  for (let n = 2; ; n += 1) if (!used.has(`${base}_${n}`)) return `${base}_${n}`;
}

/** Insert `step` into the list at `listPath`, at `index`; returns the new step's path. */
export function insertStep(doc, listPath, index, step) {
  const list = listAt(doc, listPath);
  const at = Math.max(0, Math.min(index, list.length));
  list.splice(at, 0, step);
  return [...listPath, at];
}

/** Remove the step at `path`; returns it. */
export function removeStep(doc, path) {
  const listPath = path.slice(0, -1);
  const [step] = getIn(doc, listPath).splice(path[path.length - 1], 1);
  tidyArm(doc, listPath);
  return step;
}

/** Move the step at `path` one place up (-1) or down (+1) in its list; returns its new path. */
export function shiftStep(doc, path, delta) {
  const list = getIn(doc, path.slice(0, -1));
  const from = path[path.length - 1];
  const to = from + delta;
  if (to < 0 || to >= list.length) return path;
  [list[from], list[to]] = [list[to], list[from]];
  return [...path.slice(0, -1), to];
}

/** Move the step at `from` to list `toList` before `toIndex` (drag and drop); returns its new path
 *  or null when the move is impossible (a branch into its own arm). */
export function moveStep(doc, from, toList, toIndex) {
  if (toList.length > from.length && samePath(toList.slice(0, from.length), from)) return null;
  const owner = getIn(doc, toList.slice(0, -1)); // resolved before the removal shifts any index
  const key = toList[toList.length - 1];
  const fromList = from.slice(0, -1);
  const fromOwner = getIn(doc, fromList.slice(0, -1));
  const fromKey = fromList[fromList.length - 1];
  if (!owner || !fromOwner) return null;
  const fromIndex = from[from.length - 1];
  let index = toIndex;
  if (samePath(fromList, toList) && fromIndex < toIndex) index -= 1;
  const [step] = fromOwner[fromKey].splice(fromIndex, 1);
  if (!Array.isArray(owner[key])) owner[key] = [];
  owner[key].splice(Math.max(0, Math.min(index, owner[key].length)), 0, step);
  if (fromKey === "else" && fromOwner.else.length === 0) delete fromOwner.else;
  return allSteps(doc).find((s) => s.step === step).path;
}

/** Path of the list a step is in, and a human name for it ("process lead_to_table", "else arm of any_order"). */
export function listName(doc, listPath) {
  const key = listPath[listPath.length - 1];
  if (key === "steps") return `process ${listPath[1]}`;
  const branch = getIn(doc, listPath.slice(0, -1));
  return `${key} arm of ${branch && branch.id ? branch.id : "the branch"}`;
}

/** The existing module a palette entry stands for (same robot service, same kind), or null. */
export function moduleFor(doc, entry) {
  if (entry.kind === "fire_rules" || !entry.module) return null; // every rule firing is its own module
  for (const [name, module] of Object.entries(doc.modules || {})) {
    if (module.kind !== entry.kind) continue;
    if (entry.kind === "ros_service" && module.service !== entry.module.service) continue;
    return name;
  }
  return null;
}

/** Add the module of a palette entry (and its actor) to the document; returns the module name. */
export function addModule(doc, entry, name) {
  const moduleName = uniqueModuleName(doc, name || entry.module_name || entry.kind);
  doc.modules = doc.modules || {};
  doc.modules[moduleName] = JSON.parse(JSON.stringify(entry.module));
  const actor = entry.actor;
  if (actor && doc.modules[moduleName].actor) {
    doc.actors = doc.actors || {};
    if (!doc.actors[actor.name]) doc.actors[actor.name] = { kind: actor.kind, label: actor.label };
  }
  return moduleName;
}

/** A short description of a step for the views: "say: Welcome", "if len(x) > 0", "process greet". */
export function stepSummary(step) {
  if (!step || typeof step !== "object") return "?";
  if (step.label) return step.label;
  if (step.module) {
    const w = step.with || {};
    for (const key of ["text", "name", "location", "prompt", "seconds", "facts"]) {
      if (w[key] !== undefined && w[key] !== "") return `${step.module}: ${w[key]}`;
    }
    return step.module;
  }
  if (step.if !== undefined) return `if ${step.if}`;
  if (step.process) return `process ${step.process}`;
  if (step.set) return `set ${Object.keys(step.set).join(", ")}`;
  return "step";
}

/** "processes.greet.steps[1].with.text" -> ["processes", "greet", "steps", 1, "with", "text"]. */
export function parseProblemPath(text) {
  const out = [];
  for (const m of String(text || "").matchAll(/([^.[\]]+)|\[(\d+)\]/g)) out.push(m[2] !== undefined ? Number(m[2]) : m[1]);
  return out;
}

/** Where a problem is, for the owner: {stepPath, stepId, module, field}. */
export function locateProblem(doc, problem) {
  const path = parseProblemPath(problem.path);
  if (path[0] === "modules" && path.length >= 2) return { module: path[1], field: path.slice(path[2] === "params" ? 3 : 2).join(".") };
  let stepEnd = -1;
  for (let i = 1; i < path.length; i += 1) {
    if (typeof path[i] === "number" && ["steps", "then", "else"].includes(path[i - 1])) stepEnd = i;
  }
  if (stepEnd < 0) return { field: path.join(".") };
  const stepPath = path.slice(0, stepEnd + 1);
  const step = getIn(doc, stepPath);
  return { stepPath, stepId: step && step.id, field: path.slice(stepEnd + 1).join(".") };
}

const NAME = /^[A-Za-z_][A-Za-z0-9_]*$/;

/** Why ``name`` cannot name a ``what`` (module, process, variable): "" when it can. ``taken``: the
 *  name is used already. */
export function nameProblem(what, name, taken = false) {
  if (!NAME.test(name)) return `A ${what} name is letters, digits and _ (not starting with a digit).`;
  return taken ? `There is already a ${what} “${name}”.` : "";
}

/** ``obj`` with key ``from`` renamed to ``to`` in the same place (YAML keeps the order). */
function renameKey(obj, from, to) {
  return Object.fromEntries(Object.entries(obj || {}).map(([name, v]) => [name === from ? to : name, v]));
}

/** Renames process ``from`` to ``to`` where it is defined (keeping its place), in every service
 *  that lists it and in every step that runs it; "" when done, else why not. */
export function renameProcess(doc, from, to) {
  if (from === to) return "";
  const problem = nameProblem("process", to, !!(doc.processes || {})[to]);
  if (problem) return problem;
  doc.processes = renameKey(doc.processes, from, to);
  for (const service of Object.values(doc.services || {})) {
    if (Array.isArray(service.processes)) service.processes = service.processes.map((p) => (p === from ? to : p));
  }
  for (const { step } of allSteps(doc)) if (step && step.process === from) step.process = to;
  return "";
}

/** Removes process ``name`` with its steps, and from the services that list it; returns how many
 *  steps it had. Steps that run it stay (the checks name them). */
export function removeProcess(doc, name) {
  const steps = ((doc.processes[name] || {}).steps || []).length;
  delete doc.processes[name];
  for (const service of Object.values(doc.services || {})) {
    if (Array.isArray(service.processes)) service.processes = service.processes.filter((p) => p !== name);
  }
  return steps;
}

/** The value a set step's field stands for: a number, true/false/null, else the text itself
 *  (texts and ``${…}`` expressions). */
export function variableValue(text) {
  const t = text.trim();
  if (/^-?\d+(\.\d+)?$/.test(t)) return Number(t);
  if (t === "true" || t === "false") return t === "true";
  if (t === "null") return null;
  return text;
}

/** The field text of a set step's value (the inverse of :func:`variableValue`). */
export function variableText(value) {
  return typeof value === "string" ? value : JSON.stringify(value);
}

/** Renames variable ``from`` of a set step, keeping its place; "" when done, else why not. */
export function renameVariable(step, from, to) {
  if (from === to) return "";
  const problem = nameProblem("variable", to);
  if (problem) return problem;
  if (Object.prototype.hasOwnProperty.call(step.set || {}, to)) return `The step already sets “${to}”.`;
  step.set = renameKey(step.set, from, to);
  return "";
}

/** A variable name the set step does not set yet: value, value_2, … */
export function newVariableName(step) {
  const used = new Set(Object.keys(step.set || {}));
  if (!used.has("value")) return "value";
  for (let n = 2; ; n += 1) if (!used.has(`value_${n}`)) return `value_${n}`;
}

/** Rename module `from` to `to` everywhere: its key (same place), the steps that use it, the
 *  fire-rules modules that dispatch actions to it. Returns an error sentence, or "" when done. */
export function renameModule(doc, from, to) {
  if (from === to) return "";
  const problem = nameProblem("module", to, !!(doc.modules || {})[to]);
  if (problem) return problem;
  doc.modules = renameKey(doc.modules, from, to);
  for (const { step } of allSteps(doc)) if (step && step.module === from) step.module = to;
  for (const module of Object.values(doc.modules)) {
    for (const [action, target] of Object.entries(module.dispatch || {})) if (target === from) module.dispatch[action] = to;
  }
  return "";
}

/** A step's or list's path as one string (the data-path of its element). */
export const pathKey = (path) => path.join("/");
