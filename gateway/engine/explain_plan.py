"""Explain, part 1: a rule set's rules read as conditions, and the diagnostic queries asked about them.

Why the gateway reads the conditions itself: Drools answers "what fired" but not "why not", and a
rule's conditions are text the gateway owns (DRL, the DRL a .dslr expands to, the DRL a decision
table becomes). Each rule becomes a :class:`RulePlan` — its top-level conditions, each classified
(a pattern, ``not``, ``exists``, ``or``, ``forall``, ``from``, an accumulate, an ``eval``) and
put in the author's words (the .dslr lines or the decision table cell it came from) — and the
plans become DRL queries (:func:`query_files`): ``C1 … Ck`` for each k, the candidates of a
pattern with its first j constraints, the alternatives of an ``or``, the violators of a
``forall``. :mod:`gateway.engine.explain` compiles them; :mod:`gateway.engine.explain_reasons`
reads their rows back as reasons.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from gateway.engine import compiler
from gateway.engine.errors import CompileError
from gateway.engine.ruleset import MAX_FILES

QUERY_FILE = "zz_explain_{n}.drl"
FACT = "$__f"
QUERIES_PER_PACKAGE = 40
_PACKAGE = re.compile(r"^\s*package\s+[\w.]+\s*;?")
_STRING_OR_COMMENT = re.compile(r'"(?:\\.|[^"\\\n])*"|\'(?:\\.|[^\'\\\n])*\'|//[^\n]*|/\*.*?\*/', re.DOTALL)
_PATTERN = re.compile(r"^\s*(?:(\$?[\w$]+)\s*:\s*)?([A-Za-z_$][\w$.]*)\s*\(", re.DOTALL)


# --------------------------------------------------------------------------- reading the rules


def _masked(text: str) -> str:
    """``text`` with strings and comments blanked (same length): keywords and brackets in them vanish."""
    return _STRING_OR_COMMENT.sub(lambda m: m.group(0)[0] + " " * (len(m.group(0)) - 2) + m.group(0)[-1]
                                  if m.group(0)[0] in "\"'" else re.sub(r"[^\n]", " ", m.group(0)), text)


def _close_paren(masked: str, open_at: int) -> int:
    """Index of the bracket closing the one at ``open_at`` (-1 if none)."""
    depth = 0
    for pos in range(open_at, len(masked)):
        ch = masked[pos]
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
            if depth == 0:
                return pos
    return -1


def _split_top(text: str, separators: str, *, at_and: bool = True) -> list[str]:
    """``text`` split at the ``separators`` characters (and ``&&`` unless ``at_and`` is false) that
    are outside brackets and strings."""
    masked = _masked(text)
    parts, depth, start, pos = [], 0, 0, 0
    while pos < len(text):
        ch = masked[pos]
        conjunction = at_and and masked.startswith("&&", pos)
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        elif depth == 0 and (ch in separators or conjunction):
            parts.append(text[start:pos])
            pos += 2 if conjunction else 1
            start = pos
            continue
        pos += 1
    parts.append(text[start:])
    return [p.strip() for p in parts if p.strip()]


@dataclass
class Condition:
    """One top-level condition of a rule, as DRL and as its author wrote it."""

    index: int  # 1-based
    drl: str
    line: int  # in the DRL text
    kind: str  # pattern, not, exists, accumulate, from, eval, or, forall, other
    written: str = ""
    file: str = ""
    source_line: int = 0
    cell: str = ""
    sheet: str = ""
    # a pattern's parts (for pattern, exists, from, accumulate, and the inside of not)
    binding: str | None = None
    type: str | None = None
    constraints: list[str] = field(default_factory=list)
    suffix: str = ""  # "from …", "over window:…"
    branches: list[Condition] = field(default_factory=list)  # an "or"'s alternatives, a "forall"'s patterns
    # the accumulate element ``accumulate( source; functions [; constraints] )``: its source and
    # functions (its constraints are ``constraints``); empty for every other condition
    source: str = ""
    functions: str = ""

    def where(self) -> dict[str, Any]:
        out: dict[str, Any] = {"index": self.index, "kind": self.kind, "drl": self.drl, "written": self.written,
                               "file": self.file, "line": self.source_line}
        if self.cell:
            out.update(sheet=self.sheet, cell=self.cell)
        return out

    def candidate(self, constraints: int | None = None) -> str:
        """The condition's pattern with ``constraints`` of its constraints, binding ``$__f``; of an
        accumulate element, the element with them (its rows hold what its functions bind)."""
        kept = self.constraints if constraints is None else self.constraints[:constraints]
        if self.functions:
            return f"accumulate( {self.source}; {self.functions}" + (f"; {', '.join(kept)} )" if kept else " )")
        return f"{FACT} : {self.type}( {', '.join(kept)} ) {self.suffix}".rstrip()

    def results(self) -> list[str]:
        """The variables an accumulate element's functions bind (``$t : sum( $a )`` binds ``$t``)."""
        return [m.group(1) for part in _split_top(self.functions, ",", at_and=False)
                if (m := re.match(r"\s*(\$?[\w$]+)\s*:", part))]


def _parse_pattern(cond: Condition, text: str) -> None:
    """Fill ``cond``'s pattern parts from ``text`` (``[$v :] Type( … ) [from …]``), if it is one."""
    match = _PATTERN.match(text)
    if not match:
        return
    masked = _masked(text)
    close = _close_paren(masked, match.end() - 1)
    if close < 0:
        return
    cond.binding, cond.type = match.group(1), match.group(2)
    cond.constraints = _split_top(text[match.end():close], ",")
    cond.suffix = text[close + 1:].strip()


def _parse_accumulate(cond: Condition, inner: str) -> None:
    """Fill the parts of ``accumulate( source; functions [; constraints] )`` (the inside given) when
    its functions bind results; an accumulate written otherwise (inline ``init``/``action``/``result``
    code) keeps none and is explained as a whole."""
    parts = _split_top(inner, ";", at_and=False)
    if len(parts) not in (2, 3):
        return
    cond.source, cond.functions = parts[0], parts[1]
    cond.constraints = _split_top(parts[2], ",") if len(parts) == 3 else []
    if not cond.results():
        cond.source = cond.functions = ""
        cond.constraints = []


def _unwrap(text: str) -> str:
    """``( X )`` -> ``X`` when the brackets hold all of it."""
    text = text.strip()
    if text.startswith("(") and _close_paren(_masked(text), 0) == len(text) - 1:
        return text[1:-1].strip()
    return text


def _split_or(text: str) -> list[str]:
    """``text`` split at its top-level ``or`` / ``||`` (outside brackets and strings)."""
    masked = _masked(text)
    parts, depth, start = [], 0, 0
    for match in re.finditer(r"[()\[\]{}]|\bor\b|\|\|", masked):
        tok = match.group()
        if tok in "([{":
            depth += 1
        elif tok in ")]}":
            depth -= 1
        elif depth == 0:
            parts.append(text[start:match.start()])
            start = match.end()
    parts.append(text[start:])
    return [p.strip() for p in parts if p.strip()]


def _classify_forall(cond: Condition, inner: str) -> None:
    """``forall( P0 P1 … )``: its patterns (P0 chooses the elements, the others must hold for each)."""
    cond.branches = split_conditions(inner, cond.line)
    cond.kind = "forall" if cond.branches and all(b.kind == "pattern" for b in cond.branches) else "other"


def classify(cond: Condition) -> None:
    """Set the condition's kind and pattern parts from its DRL."""
    text = cond.drl.strip()
    head = re.match(r"^(not|exists|eval|forall|accumulate)\b", text)
    if head and head.group(1) == "forall":
        _classify_forall(cond, _unwrap(text[head.end():]))
        return
    alternatives = _split_or(_unwrap(text)) if not head or head.group(1) not in ("eval", "accumulate") else []
    if len(alternatives) > 1:
        cond.kind = "or"
        cond.branches = [Condition(b, alt, cond.line, "other") for b, alt in enumerate(alternatives, start=1)]
        for branch in cond.branches:
            classify(branch)
        return
    if head:
        cond.kind = head.group(1)
        if cond.kind in ("not", "exists"):
            _parse_pattern(cond, _unwrap(text[head.end():]))
            if cond.type is None or re.search(r"\b(or|and)\b|\|\||&&", _masked(cond.suffix)):
                cond.kind = "other"  # not( A or B ), exists( A and B ): not one pattern's facts
        elif cond.kind == "accumulate":
            _parse_accumulate(cond, _unwrap(text[head.end():]))
        return
    _parse_pattern(cond, text)
    if cond.type is None:
        cond.kind = "other"
    elif re.match(r"^from\s+(accumulate|acc)\b", cond.suffix):
        cond.kind = "accumulate"
    elif cond.suffix.startswith("from"):
        cond.kind = "from"
    else:
        cond.kind = "pattern"
    if cond.type is not None and re.search(r"\b(or|\|\|)\b", _masked(cond.suffix)):
        cond.kind = "other"


_TOKEN = re.compile(r"\$?[\w$.]+|&&|\|\||\S")
_NOT_AFTER = {"from", "over", "or", "and", "&&", "||", "not", "exists", "forall", ":", ",", "accumulate", "acc",
              "collect", "window", "entry-point", "."}
_NOT_BEFORE = {"from", "over", "or", "and", "&&", "||", ")", "]", "}", ".", ",", ":", "(", "[", "{", "-"}


def split_conditions(lhs: str, first_line: int) -> list[Condition]:
    """A rule's ``when`` part as its top-level conditions, each with the DRL line it starts on.

    A condition ends after a closing bracket at the top level (``Guest( … )``) or at a line end
    after a word (``from $order.items``) when the next word cannot continue it (``from``, ``or``,
    ``over`` …): a DSL sentence that expands to two conditions on one line gives two."""
    masked = _masked(lhs)
    starts: list[int] = []
    depth, prev, prev_end = 0, None, 0
    for match in _TOKEN.finditer(masked):
        tok = match.group()
        if depth == 0:
            if tok == ";":
                prev = None
                continue
            fresh = prev is None or (tok not in _NOT_BEFORE and prev not in _NOT_AFTER
                                     and (prev == ")" or "\n" in masked[prev_end:match.start()]))
            if fresh:
                starts.append(match.start())
        if tok in "([{":
            depth += 1
        elif tok in ")]}":
            depth -= 1
        if depth == 0:
            prev, prev_end = (")" if tok in ")]}" else tok), match.end()
    out = []
    for index, begin in enumerate(starts, start=1):
        stop = starts[index] if index < len(starts) else len(lhs)
        text = lhs[begin:stop].strip().rstrip(";").strip()
        cond = Condition(index, text, first_line + lhs[:begin].count("\n"), "other")
        classify(cond)
        out.append(cond)
    return out


@dataclass
class RulePlan:
    """One rule: where it is, its conditions, and the names of its diagnostic queries."""

    name: str
    number: int  # position in the rule set (query names use it: rule names may hold anything)
    file: str
    line: int
    conditions: list[Condition]
    broken: str = ""  # why it cannot be explained (its queries did not compile)
    attributes: dict[str, str] = field(default_factory=dict)  # its file's and its own (rule_attributes): what can hold it back
    _names: dict[int, list[str]] = field(default_factory=dict, repr=False)

    def condition_names(self, k: int) -> list[str]:
        """The names of :func:`_condition_queries` of condition ``k`` (kept: every explanation asks them)."""
        if k not in self._names:
            self._names[k] = [name for name, _body in _condition_queries(self, k)]
        return self._names[k]

    def prefix_name(self, k: int) -> str:
        return f"why__{self.number}__{k}"

    def prefix_query(self, k: int) -> str:
        """The query ``C1 … Ck``: for a pattern, its candidate query with all its constraints."""
        cond = self.conditions[k - 1]
        if has_candidates(cond) and cond.kind != "not":
            return self.candidate_query(k, len(cond.constraints))
        return self.prefix_name(k)

    def candidate_query(self, k: int, j: int) -> str:
        return f"why__{self.number}__{k}__c{j}"

    def branch_query(self, k: int, b: int, j: int | None = None) -> str:
        """Alternative ``b`` of the "or" condition ``k``: its candidates (``j`` constraints), or itself."""
        return f"why__{self.number}__{k}__o{b}" + ("" if j is None else f"__c{j}")

    def violators_query(self, k: int, j: int | None = None) -> str:
        """The elements that break the "forall" condition ``k`` (``j``: those failing its j-th constraint)."""
        return f"why__{self.number}__{k}__v" + ("" if j is None else str(j))


_RULE_NAME = re.compile(r'^\s*rule\s+(?:"(?:\\.|[^"\\])*"|\'(?:\\.|[^\'\\])*\'|\S+)')
_ATTRIBUTE = re.compile(r'(?<![\w-])(agenda-group|activation-group|auto-focus|no-loop|lock-on-active|date-effective|'
                        r'date-expires|enabled)(?![\w-])\s*(?:"((?:\\.|[^"\\])*)"|\'((?:\\.|[^\'\\])*)\'|(true|false)\b)?')


def rule_attributes(header: str) -> dict[str, str]:
    """The attributes written in a rule's header (``rule "n" … when``), or in a file's header for all
    its rules, that can keep a rule whose conditions hold from firing, by name: a text's value,
    ``true``/``false``, or ``true`` for a bare flag (``no-loop``)."""
    name = _RULE_NAME.match(header)
    text = header[name.end():] if name else header
    out: dict[str, str] = {}
    for m in _ATTRIBUTE.finditer(_masked(text)):  # strings blanked: their words are no attributes
        quoted = 2 if m.group(2) is not None else 3 if m.group(3) is not None else None
        out[m.group(1)] = text[m.start(quoted):m.end(quoted)] if quoted else (m.group(4) or "true")
    return out


def _rule_lhs(text: str) -> tuple[int, int] | None:
    """(start, end) of the ``when`` part of one rule's text."""
    masked = _masked(text)
    when = re.search(r"\bwhen\b", masked)
    if when is None:
        return None
    then = re.search(r"\bthen\b", masked[when.end():])
    if then is None:
        return None
    return when.end(), when.end() + then.start()


def _sentences(original: str, rule: str) -> list[tuple[int, list[str]]]:
    """The when-part of rule ``rule`` in a .dslr as its sentences: (line, [the sentence, its "- " lines])."""
    head = re.search(r'^\s*rule\s+"?' + re.escape(rule) + r'"?', original, re.MULTILINE)
    if head is None:
        return []
    lines = original[head.start():].split("\n")
    first = original[:head.start()].count("\n") + 1
    out: list[tuple[int, list[str]]] = []
    inside = False
    for offset, line in enumerate(lines):
        text = line.strip()
        if not inside:
            inside = bool(re.match(r"^when\b", text))
            continue
        if re.match(r"^then\b", text):
            break
        if not text or text.startswith(("//", "#")):
            continue
        if text.startswith("-") and out:
            out[-1][1].append(text)
        else:
            out.append((first + offset, [text]))
    return out


def _author_words(source: Any, conditions: list[Condition], lhs: str, first_line: int, rule: str,
                  original: str | None) -> None:
    """Fill each condition's file, line and written text: the .dslr sentence (with its "- " lines)
    it was expanded from — the expander turns each sentence into one DRL line, in order —, the
    decision table cell its DRL line came from, or the DRL itself."""
    sentences = _sentences(original, rule) if original is not None else []
    drl_lines = [first_line + n for n, line in enumerate(lhs.split("\n"))
                 if line.strip() and not line.strip().startswith(("//", "#"))]
    for cond in conditions:
        cond.file = source.file
        cond.source_line = source.source_line(cond.line)
        cond.written = cond.drl
        if source.table is not None:
            located = source.table.locate(CompileError(source.file, cond.line, 0, ""))
            cond.sheet, cond.cell = located.sheet, located.cell
            cond.written = _table_words(source.table, cond) or cond.drl
        elif sentences and cond.line in drl_lines and drl_lines.index(cond.line) < len(sentences):
            line, words = sentences[drl_lines.index(cond.line)]
            cond.source_line, cond.written = line, "\n".join(words)


def _table_words(table: Any, cond: Condition) -> str:
    """A decision table condition in the table's words: the texts of the cells its DRL lines came
    from, each value with its column's label (``$g: Group`` / ``Kind: pair`` / ``At least: 2``)."""
    seen, words = set(), []
    for line in range(cond.line, cond.line + cond.drl.count("\n") + 1):
        cell = table.cells[line - 1] if 0 < line <= len(table.cells) else None
        if cell is None or (cell.row, cell.col) in seen:
            continue
        seen.add((cell.row, cell.col))
        text = table.cell_words(cell)
        if text:
            words.append(text)
    return "\n".join(words)


def plan_rules(files: dict[str, str]) -> tuple[list[RulePlan], list[tuple[Any, Any]]]:
    """Every rule of ``files`` with its conditions, and the DRL sources (with items) they are in."""
    plans: list[RulePlan] = []
    sources = compiler.rule_sources(files)
    for source, items in sources:
        if items is None:
            continue
        original = files.get(source.file) if source.line_map is not None else None
        package = rule_attributes(items.header())  # the file's own attributes: every rule of it has them
        for item in items.rules:
            text = items.item_text(item)
            lhs = _rule_lhs(text)
            if lhs is None:
                continue
            first_line = item.line + text[:lhs[0]].count("\n")
            conditions = split_conditions(text[lhs[0]:lhs[1]], first_line)
            _author_words(source, conditions, text[lhs[0]:lhs[1]], first_line, item.name, original)
            plans.append(RulePlan(item.name, len(plans) + 1, source.file, source.source_line(item.line), conditions,
                                  attributes={**package, **rule_attributes(text[:lhs[0]])}))
    return plans, sources


# --------------------------------------------------------------------------- the queries


def has_candidates(cond: Condition) -> bool:
    """Whether the condition has candidate queries (:meth:`Condition.candidate`): a pattern of a
    type, or an accumulate element whose functions bind results."""
    return (cond.type is not None or bool(cond.functions)) and cond.kind != "other"


def _queries(plan: RulePlan) -> list[tuple[str, str]]:
    """(name, DRL) of a rule's diagnostic queries: per condition k, ``C1 … Ck`` and what
    explaining condition k needs (:func:`_condition_queries`)."""
    out = []
    for k, cond in enumerate(plan.conditions, start=1):
        if plan.prefix_query(k) == plan.prefix_name(k):
            before = [c.drl for c in plan.conditions[:k - 1]]
            out.append((plan.prefix_query(k), "\n    ".join(before + [cond.drl])))
        out.extend(_condition_queries(plan, k))
    return out


def _condition_queries(plan: RulePlan, k: int) -> list[tuple[str, str]]:
    """(name, DRL) of the queries that explain condition ``k`` once ``C1 … Ck`` has no row:

    - a pattern: ``C1 … Ck-1, $__f : Type(c1 … cj)`` for each j (the last one is ``C1 … Ck``);
    - an "or": the same for each alternative that is a pattern (or its blockers for a "not"), and
      ``C1 … Ck-1, alternative`` for any other;
    - a "forall": its violators ``C1 … Ck-1, P0, not( P1 and … )`` (for one pattern: the facts of
      its type that do not match it, and those failing each of its constraints)."""
    cond = plan.conditions[k - 1]
    before = [c.drl for c in plan.conditions[:k - 1]]

    def query(*parts: str) -> str:
        return "\n    ".join(before + list(parts))

    out: list[tuple[str, str]] = []
    if has_candidates(cond):
        out.extend((plan.candidate_query(k, j), query(cond.candidate(j))) for j in range(len(cond.constraints) + 1))
    elif cond.kind == "or":
        for branch in cond.branches:
            if has_candidates(branch):
                first = len(branch.constraints) if branch.kind == "not" else 0
                out.extend((plan.branch_query(k, branch.index, j), query(branch.candidate(j)))
                           for j in range(first, len(branch.constraints) + 1))
            else:
                out.append((plan.branch_query(k, branch.index), query(branch.drl)))
    elif cond.kind == "forall":
        first, rest = cond.branches[0], cond.branches[1:]
        if rest:
            chosen = first.drl if first.binding else f"{FACT} : {first.drl}"
            out.append((plan.violators_query(k), query(chosen, "not( " + " and ".join(r.drl for r in rest) + " )")))
        else:
            every = f"{FACT} : {first.type}( )"
            out.append((plan.violators_query(k),
                        query(every, f"not( {first.type}( this == {FACT}, {', '.join(first.constraints)} ) )")))
            out.extend((plan.violators_query(k, j), query(every, f"not( {first.type}( this == {FACT}, {c} ) )"))
                       for j, c in enumerate(first.constraints))
    return out


def _chunks(each: list[tuple[str, list[str]]], per_package: int) -> list[tuple[str, list[str]]]:
    """Each file's queries in packages of at most ``per_package`` (a rule's queries kept together)."""
    chunks: list[tuple[str, list[str]]] = []
    for file, texts in each:
        if not chunks or chunks[-1][0] != file or len(chunks[-1][1]) + len(texts) > per_package:
            chunks.append((file, []))
        chunks[-1][1].extend(texts)
    return chunks


def query_files(plans: list[RulePlan], sources: list[tuple[Any, Any]], skip: set[int] = frozenset()) -> dict[str, str]:
    """The diagnostic queries as DRL files, each its own package of at most QUERIES_PER_PACKAGE
    queries (one package of hundreds of queries exceeds the JVM's method size limit), importing
    every declared type and keeping the rule's file's imports and globals."""
    declared = sorted({f"{items.package}.{item.name.rsplit('.', 1)[-1]}" for _src, items in sources if items is not None
                       for item in items.items if item.kind in ("type", "enum")})
    headers = {src.file: (items.package, _PACKAGE.sub("", items.header()))
               for src, items in sources if items is not None}
    each = [(plan.file, [f'query "{name}"\n    {body}\nend\n' for name, body in _queries(plan)])
            for plan in plans if plan.number not in skip and not plan.broken]
    # bigger packages where small ones would pass the files a rule set may have (a large rule set):
    # the queries of the plain shapes are not compiled, so the method size limit does not bind them
    budget = MAX_FILES - len(sources)  # the declarations go with them, a file each
    per_package = QUERIES_PER_PACKAGE
    chunks = _chunks(each, per_package)
    while len(chunks) > budget and per_package < sum(len(texts) for _, texts in each):
        per_package *= 2
        chunks = _chunks(each, per_package)
    out = {}
    for n, (fname, texts) in enumerate(chunks, start=1):
        package, header = headers.get(fname, ("defaultpkg", ""))
        imports = "\n".join(f"import {name};" for name in declared if name.rsplit(".", 1)[0] != f"{package}.why{n}")
        body = "\n".join(texts)
        out[QUERY_FILE.format(n=n)] = f"package {package}.why{n};\n{imports}\n{_used_globals(header, body)}\n\n{body}"
    return out


_GLOBAL = re.compile(r"\bglobal\s+[\w.$]+(?:\s*<[^;]*?>)?(?:\s*\[\s*\])*\s+([\w$]+)\s*;?")


def _used_globals(header: str, body: str) -> str:
    """The header without the globals ``body`` does not name. Why: a file of queries that declares
    no global and whose queries all build plain needs nothing of the declarations unit, which is
    then the rule set's own, already built (``drl_items.RuleSetItems.declarations_key``)."""
    names = set(re.findall(r"[\w$]+", body))
    return _GLOBAL.sub(lambda m: m.group(0) if m.group(1) in names else "", header)
