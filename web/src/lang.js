// Syntax highlighting for Drools files (.drl, .dslr, .dsl). CodeMirror has no Drools grammar, so
// these are small line tokenizers (StreamLanguage): enough to colour keywords, strings, comments,
// $bindings, fact types and DSL {placeholders}; the real check is the server's compiler.

import { StreamLanguage, LanguageSupport } from "@codemirror/language";
import { json } from "@codemirror/lang-json";
import { yaml } from "@codemirror/lang-yaml";

const KEYWORDS = new Set(
  ("package import global rule query declare function when then end extends dialect attributes " +
    "salience no-loop lock-on-active agenda-group activation-group ruleflow-group auto-focus " +
    "date-effective date-expires enabled duration timer calendars expander " +
    "and or not exists forall accumulate collect from over window entry-point eval init action " +
    "reverse result in matches memberOf contains soundslike str after before coincides during " +
    "finishes includes meets overlaps starts modify insert insertLogical retract delete update " +
    "new return if else this true false null").split(" ")
);

function inLineComment(stream) {
  // "#" starts a comment only at the start of a line (it is also used inside Java strings).
  return stream.string.slice(0, stream.pos).trim() === "" && stream.peek() === "#";
}

/** One DRL token; shared by the DRL/DSLR modes and the code side of DSL entries. */
function drlToken(stream, state, colourTypes = true) {
  if (state.inBlockComment) {
    if (stream.skipTo("*/")) {
      stream.pos += 2;
      state.inBlockComment = false;
    } else stream.skipToEnd();
    return "comment";
  }
  if (stream.eatSpace()) return null;
  if (stream.match("//") || inLineComment(stream)) {
    stream.skipToEnd();
    return "comment";
  }
  if (stream.match("/*")) {
    state.inBlockComment = true;
    return "comment";
  }
  if (stream.sol() && stream.match(/^>/)) return "meta"; // DSLR: the rest of the line is raw DRL
  const quote = stream.peek();
  if (quote === '"' || quote === "'") {
    stream.next();
    let escaped = false;
    for (let ch = stream.next(); ch !== undefined; ch = stream.next()) {
      if (ch === quote && !escaped) break;
      escaped = !escaped && ch === "\\";
    }
    return "string";
  }
  if (stream.match(/^\$[\w$]*/)) return "variableName";
  if (stream.match(/^@[\w.-]+/)) return "meta";
  if (stream.match(/^-?\d+(\.\d+)?[lLdDfF]?/)) return "number";
  if (stream.match(/^[A-Za-z_][\w-]*/)) {
    let word = stream.current();
    if (!KEYWORDS.has(word) && word.includes("-")) {
      // Only attribute keywords contain "-": give the rest back ("a-b" is a minus in code).
      stream.backUp(word.length - word.indexOf("-"));
      word = stream.current();
    }
    if (KEYWORDS.has(word)) return "keyword";
    return colourTypes && /^[A-Z]/.test(word) ? "typeName" : null;
  }
  if (stream.match(/^[=!<>]=?|^&&|^\|\||^[+\-*/%:]/)) return "operator";
  stream.next();
  return null;
}

const drlMode = {
  name: "drl",
  startState: () => ({ inBlockComment: false }),
  token: drlToken,
  languageData: { commentTokens: { line: "//", block: { open: "/*", close: "*/" } } },
};

// A DSL file is a list of entries "[when]A sentence with {value}=DRL code with {value}".
const dslMode = {
  name: "dsl",
  startState: () => ({ inBlockComment: false, part: "start" }),
  token(stream, state) {
    if (stream.sol()) state.part = "start";
    if (state.part === "start") {
      if (stream.eatSpace()) return null;
      if (stream.match("#") || stream.match("//")) {
        stream.skipToEnd();
        return "comment";
      }
      if (stream.match(/^\[[^\]]*\]/)) return "keyword";
      state.part = "sentence";
    }
    if (state.part === "sentence") {
      if (stream.match(/^\{[^}]*\}/)) return "variableName";
      if (stream.match("\\=") || stream.match("\\{")) return "string";
      if (stream.eat("=")) {
        state.part = "code";
        return "operator";
      }
      stream.match(/^[^{=\\]+/) || stream.next();
      return "string";
    }
    if (stream.match(/^\{[^}]*\}/)) return "variableName";
    return drlToken(stream, state);
  },
  languageData: { commentTokens: { line: "#" } },
};

// In a .dslr, capitalised words are mostly ordinary words of sentences, not fact types.
const dslrMode = { ...drlMode, name: "dslr", token: (stream, state) => drlToken(stream, state, false) };

const drlLanguage = StreamLanguage.define(drlMode);
const dslrLanguage = StreamLanguage.define(dslrMode);
const dslLanguage = StreamLanguage.define(dslMode);

/** The language support for a file name ([] for plain text). */
export function languageFor(fileName) {
  const lower = fileName.toLowerCase();
  if (lower.endsWith(".dsl")) return new LanguageSupport(dslLanguage);
  if (lower.endsWith(".dslr")) return new LanguageSupport(dslrLanguage);
  if (lower.endsWith(".drl")) return new LanguageSupport(drlLanguage);
  if (lower.endsWith(".json")) return json();
  if (lower.endsWith(".yaml") || lower.endsWith(".yml")) return yaml();
  return [];
}
