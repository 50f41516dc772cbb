"""The SWRL rules one by one: numbered, parsed into atoms, said in words, checked where they are wrong.

Why: the owner edits one rule ("the child seat rule"), not a file. The rules file keeps one rule per
line with ``#`` comments; rule *n* is the n-th rule line and the comment lines just above it are its
description. A rule is first checked here (``->`` once, every atom ``Name(args)`` with a known
class, property or built-in and the right number of arguments, head variables bound in the body),
so an error names the rule, line, column and atom; then Pellet checks it with everything else.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from gateway.ontology.model import OntologyModel

# owlready2's SWRL built-ins (written without "swrlb:"), with how many arguments each takes (None: any).
BUILTINS: dict[str, int | None] = {
    "equal": 2, "notEqual": 2, "lessThan": 2, "lessThanOrEqual": 2, "greaterThan": 2, "greaterThanOrEqual": 2,
    "add": None, "subtract": 3, "multiply": None, "divide": 3, "integerDivide": 3, "mod": 3, "pow": 3,
    "unaryPlus": 2, "unaryMinus": 2, "abs": 2, "ceiling": 2, "floor": 2, "round": 2, "roundHalfToEven": 2,
    "sin": 2, "cos": 2, "tan": 2, "booleanNot": 2, "stringEqualIgnoreCase": 2, "stringConcat": None,
    "substring": None, "stringLength": 2, "normalizeSpace": 2, "upperCase": 2, "lowerCase": 2, "translate": 4,
    "contains": 2, "containsIgnoreCase": 2, "startsWith": 2, "endsWith": 2, "substringBefore": 3,
    "substringAfter": 3, "matches": None, "replace": None, "tokenize": None,
}
_COMPARISONS = {"lessThan": "<", "lessThanOrEqual": "≤", "greaterThan": ">", "greaterThanOrEqual": "≥",
                "equal": "=", "notEqual": "≠"}
_ARITHMETIC = {"add": "+", "subtract": "−", "multiply": "×", "divide": "÷", "mod": "mod", "pow": "^"}
_VERBS = {"has", "is", "needs", "contains", "wants", "likes", "sits", "serves", "holds"}
_ARG = re.compile(r'\?[A-Za-z_][\w-]*|"(?:[^"\\]|\\.)*"|[+-]?\d+(?:\.\d+)?(?:[eE][+-]?\d+)?|true|false|[A-Za-z_][\w.-]*')


@dataclass
class Atom:
    name: str
    args: list[str]
    column: int  # 1-based, in the rule's text
    text: str

    @property
    def variables(self) -> list[str]:
        return [a for a in self.args if a.startswith("?")]


@dataclass
class Rule:
    number: int
    line: int  # 1-based line in the rules file
    text: str
    comment: str = ""
    body: list[Atom] = field(default_factory=list)
    head: list[Atom] = field(default_factory=list)


class RuleInvalid(ValueError):
    """A rule that is wrong before any reasoning: where (column, atom) and what."""

    def __init__(self, message: str, column: int = 0, atom: str = "") -> None:
        super().__init__(message)
        self.message, self.column, self.atom = message, column, atom


def rule_lines(text: str) -> list[tuple[int, str, str]]:
    """(line number, rule text, comment above it) per rule line of a rules file."""
    out, comment = [], []
    for i, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not stripped:
            comment = []
        elif stripped.startswith("#"):
            comment.append(stripped.lstrip("#").strip())
        else:
            out.append((i, stripped, " ".join(comment)))
            comment = []
    return out


def parse_atoms(text: str, offset: int = 0) -> list[Atom]:
    """``A(?x), b(?x, 1)`` → atoms; RuleInvalid with the column of what is wrong."""
    atoms, i, n = [], 0, len(text)
    while i < n:
        while i < n and text[i].isspace():
            i += 1
        if i >= n:
            break
        m = re.compile(r"([A-Za-z_][\w.-]*)\s*\(").match(text, i)
        if not m:
            raise RuleInvalid(f"expected an atom like Name(?x) at {text[i:i + 20]!r}", offset + i + 1, text[i:i + 20])
        j, args, start = m.end(), [], i
        while True:
            while j < n and text[j].isspace():
                j += 1
            a = _ARG.match(text, j)
            if not a:
                raise RuleInvalid(f"{m.group(1)}: expected an argument (?variable, number, \"text\" or name) "
                                  f"at column {offset + j + 1}", offset + j + 1, text[start:j + 1])
            args.append(a.group(0))
            j = a.end()
            while j < n and text[j].isspace():
                j += 1
            if j < n and text[j] == ",":
                j += 1
                continue
            if j < n and text[j] == ")":
                j += 1
                break
            raise RuleInvalid(f"{m.group(1)}: expected ',' or ')' at column {offset + j + 1}", offset + j + 1,
                              text[start:j + 1])
        atoms.append(Atom(m.group(1), args, offset + start + 1, text[start:j]))
        while j < n and text[j].isspace():
            j += 1
        if j < n:
            if text[j] != ",":
                raise RuleInvalid(f"expected ',' between atoms at column {offset + j + 1}", offset + j + 1, text[start:j + 1])
            j += 1
        i = j
    return atoms


def parse_rule(text: str, model: OntologyModel | None = None) -> tuple[list[Atom], list[Atom]]:
    """Body and head of one rule, checked against the ontology's vocabulary when ``model`` is given."""
    if text.count("->") != 1:
        raise RuleInvalid("a rule is 'body atoms -> head atoms' with exactly one '->'", text.find("->") + 1)
    arrow = text.index("->")
    body = parse_atoms(text[:arrow])
    head = parse_atoms(text[arrow + 2:], arrow + 2)
    if not body or not head:
        raise RuleInvalid("a rule needs at least one atom before and after '->'", arrow + 1, "->")
    if model is not None:
        for atom in body + head:
            _check_atom(atom, model, atom in head)
        bound = {v for atom in body for v in atom.variables}
        for atom in head:
            for v in atom.variables:
                if v not in bound:
                    raise RuleInvalid(f"{v} in the conclusion does not appear before '->'", atom.column, atom.text)
    return body, head


def _check_atom(atom: Atom, model: OntologyModel, in_head: bool) -> None:
    name, arity = atom.name, len(atom.args)
    if name in model.classes:
        expected = 1
    elif name in model.properties:
        expected = 2
    elif name in BUILTINS:
        if in_head:
            raise RuleInvalid(f"the built-in {name} cannot be a conclusion", atom.column, atom.text)
        expected = BUILTINS[name] or arity
    else:
        raise RuleInvalid(f"{name!r} is not a class, property or built-in of the ontology", atom.column, atom.text)
    if arity != expected:
        raise RuleInvalid(f"{name} takes {expected} argument{'s' if expected != 1 else ''}, not {arity}",
                          atom.column, atom.text)
    individual_args = atom.args if name in model.classes else atom.args[:1] if name in model.properties else []
    if name in model.properties and model.properties[name].kind == "object":
        individual_args = atom.args
    for arg in individual_args:
        if not arg.startswith("?") and (arg.startswith('"') or _is_literal(arg) or arg not in model.individuals):
            raise RuleInvalid(f"{name}: {arg} is not a ?variable or an individual of the ontology", atom.column, atom.text)
    if name in model.properties and model.properties[name].kind == "data":
        value = atom.args[1]
        if not (value.startswith(("?", '"')) or _is_literal(value)):
            raise RuleInvalid(f"{name}: {value} is not a ?variable or a value (number, \"text\", true, false)",
                              atom.column, atom.text)


def _is_literal(arg: str) -> bool:
    return arg in ("true", "false") or bool(re.fullmatch(r"[+-]?\d+(\.\d+)?([eE][+-]?\d+)?", arg))


def read_rules(text: str, model: OntologyModel | None = None) -> list[Rule]:
    """Every rule of a rules file, numbered; a rule that does not parse keeps empty atoms."""
    rules = []
    for number, (line, rule_text, comment) in enumerate(rule_lines(text), 1):
        rule = Rule(number, line, rule_text, comment)
        try:
            rule.body, rule.head = parse_rule(rule_text, model)
        except RuleInvalid:
            pass
        rules.append(rule)
    return rules


def replace_rule(text: str, number: int, new_rule: str) -> str:
    """The rules file with rule ``number`` replaced by ``new_rule`` (comments and other lines kept)."""
    lines = text.splitlines(keepends=True)
    found = rule_lines(text)
    if not 1 <= number <= len(found):
        raise IndexError(f"there is no rule {number} (rules 1-{len(found)})")
    line = found[number - 1][0]
    ending = "\n" if lines[line - 1].endswith("\n") else ""
    lines[line - 1] = new_rule.strip() + ending
    return "".join(lines)


def append_rule(text: str, new_rule: str, comment: str = "") -> str:
    """The rules file with a new rule (and its comment) at the end."""
    block = (f"\n# {comment.strip()}\n" if comment.strip() else "\n") + new_rule.strip() + "\n"
    return text.rstrip("\n") + "\n" + block


def words(name: str) -> str:
    """``needsChildSeat`` → "needs child seat"."""
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", " ", name).replace("_", " ").lower()


def say_atom(atom: Atom, model: OntologyModel | None) -> str:
    a = atom.args
    if model is not None and atom.name in model.classes or (model is None and len(a) == 1 and atom.name[:1].isupper()):
        article = "an" if atom.name[:1].lower() in "aeiou" else "a"
        return f"{a[0]} is {article} {atom.name}"
    if atom.name in _COMPARISONS and len(a) == 2:
        return f"{a[0]} {_COMPARISONS[atom.name]} {a[1]}"
    if atom.name in _ARITHMETIC and len(a) >= 3:
        return f"{a[0]} = " + f" {_ARITHMETIC[atom.name]} ".join(a[1:])
    if len(a) == 2:
        said = words(atom.name)
        verb = said.split(" ", 1)[0]
        if verb in _VERBS or verb.endswith("ed"):
            if a[1] == "true":
                return f"{a[0]} {said}"
            return f"{a[0]} {said} {a[1]}"
        return f"{a[0]}'s {said} is {a[1]}"
    return atom.text


def readable(rule: Rule, model: OntologyModel | None = None) -> str:
    """The rule in words: "If ?c is a Customer and ?c has age ?a and ?a < 7, then ?c has needs child seat true"."""
    if not rule.body:
        return rule.text
    return ("If " + " and ".join(say_atom(a, model) for a in rule.body) + ", then "
            + " and ".join(say_atom(a, model) for a in rule.head) + ".")


def describe(rule: Rule, model: OntologyModel | None = None) -> dict[str, Any]:
    return {"number": rule.number, "line": rule.line, "text": rule.text, "comment": rule.comment,
            "readable": readable(rule, model),
            "body": [{"name": a.name, "args": a.args, "column": a.column, "text": a.text} for a in rule.body],
            "head": [{"name": a.name, "args": a.args, "column": a.column, "text": a.text} for a in rule.head],
            "concludes": sorted({a.name for a in rule.head})}
