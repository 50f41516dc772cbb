// A step or module field as the workflow form labels it, for problem messages: the form shows a
// step's parameter "text", not its YAML path "with.text"; a set step's "set.greeting" is the
// variable "greeting"; a module's "params.robot" is "robot".

/** "with.text" -> "text", "set.greeting" -> "variable greeting", "params.robot" -> "robot". */
export function fieldLabel(field) {
  if (!field) return "";
  const text = String(field);
  if (text.startsWith("with.")) return text.slice(5);
  if (text.startsWith("params.")) return text.slice(7);
  if (text.startsWith("set.")) return `variable ${text.slice(4)}`;
  return text;
}
