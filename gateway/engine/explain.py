"""Explain: why each rule of a version fired on some facts, or which condition stopped it.

Drools answers "what fired" but not "why not". A rule's conditions are text the gateway owns,
though (DRL, the DRL a .dslr expands to, the DRL a decision table becomes), so the question is
asked to Drools itself, as diagnostic queries compiled with the rule set through the executable
model (see /work/shared/design/explain-and-durable-sessions.md):

1. For a rule with top-level conditions C1 … Cn, the query ``C1 … Ck`` for each k: the first k
   whose query has no row is the condition that stopped the rule (earlier bindings are kept, since
   the query holds the conditions before it).
2. Inside that condition's pattern ``Type(c1, …, cm)``, the queries ``C1 … Ck-1, $f : Type(c1 … cj)``:
   every candidate fact of the type, and how many of the constraints in order it passes. The fact
   that passes most came closest; the constraint after them is the one that failed, and its field's
   value in that fact is what to show ("language is "fr", the rule wants "en"").
3. ``not X``: the X facts that exist; ``exists X``: as a pattern (none passes); a value ``from
   accumulate``: the accumulated value against its constraint; ``from expr``: the items of the source.

Queries run in a throwaway session holding the facts after the rules fired (the then-parts'
``modify``s included) — nothing is recorded, nothing reaches a robot. Generating and compiling the
queries costs a build: it is done once per version (or draft text) and cached, off the serving path.
Conditions are shown in the author's words: the .dslr lines (sentence and ``-`` lines) a condition
was expanded from, or the decision table cell its DRL line came from.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from collections import OrderedDict, deque
from dataclasses import dataclass, field
from typing import Any, Callable

import orjson

from gateway.engine import compiler, warmup
from gateway.engine.errors import CompileError, CompileFailed, EngineError, FactError
from gateway.engine.results import FireResult, decode_result, encode_facts
from gateway.engine.ruleset import content_hash

log = logging.getLogger(__name__)

QUERY_FILE = "zz_explain_{n}.drl"
FACT = "$__f"
CACHE_SIZE = 8
QUERIES_PER_PACKAGE = 40
MAX_SHOWN = 10  # facts shown for a condition (the blockers of a "not"); a query's other rows are not read
MAX_WAITING = 8  # explanations queued or running per process; more are refused (429)
_PACKAGE = re.compile(r"^\s*package\s+[\w.]+\s*;?")
_STRING_OR_COMMENT = re.compile(r'"(?:\\.|[^"\\\n])*"|\'(?:\\.|[^\'\\\n])*\'|//[^\n]*|/\*.*?\*/', re.DOTALL)
_PATTERN = re.compile(r"^\s*(?:(\$?[\w$]+)\s*:\s*)?([A-Za-z_$][\w$.]*)\s*\(", re.DOTALL)
_FIELD = re.compile(r"^\s*(?:\$?[\w$]+\s*:\s*)?([A-Za-z_$][\w$.]*)")
_EQUALS = re.compile(r"^\s*(?:\$?[\w$]+\s*:\s*)?[A-Za-z_$][\w$.]*\s*==\s*(.+?)\s*$", re.DOTALL)


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


def _split_top(text: str, separators: str) -> list[str]:
    """``text`` split at the ``separators`` characters (and ``&&``) that are outside brackets and strings."""
    masked = _masked(text)
    parts, depth, start, pos = [], 0, 0, 0
    while pos < len(text):
        ch = masked[pos]
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
        elif depth == 0 and (ch in separators or masked.startswith("&&", pos)):
            parts.append(text[start:pos])
            pos += 2 if masked.startswith("&&", pos) else 1
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

    def where(self) -> dict[str, Any]:
        out: dict[str, Any] = {"index": self.index, "kind": self.kind, "drl": self.drl, "written": self.written,
                               "file": self.file, "line": self.source_line}
        if self.cell:
            out.update(sheet=self.sheet, cell=self.cell)
        return out

    def candidate(self, constraints: int | None = None) -> str:
        """The condition's pattern with ``constraints`` of its constraints, binding ``$__f``."""
        kept = self.constraints if constraints is None else self.constraints[:constraints]
        return f"{FACT} : {self.type}( {', '.join(kept)} ) {self.suffix}".rstrip()


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
            if cond.type is None:
                cond.kind = "other"
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
        if _has_candidates(cond) and cond.kind != "not":
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
        for item in items.rules:
            text = items.item_text(item)
            lhs = _rule_lhs(text)
            if lhs is None:
                continue
            first_line = item.line + text[:lhs[0]].count("\n")
            conditions = split_conditions(text[lhs[0]:lhs[1]], first_line)
            _author_words(source, conditions, text[lhs[0]:lhs[1]], first_line, item.name, original)
            plans.append(RulePlan(item.name, len(plans) + 1, source.file, source.source_line(item.line), conditions))
    return plans, sources


# --------------------------------------------------------------------------- the queries


def _has_candidates(cond: Condition) -> bool:
    return cond.type is not None and cond.kind != "other"


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
    if _has_candidates(cond):
        out.extend((plan.candidate_query(k, j), query(cond.candidate(j))) for j in range(len(cond.constraints) + 1))
    elif cond.kind == "or":
        for branch in cond.branches:
            if _has_candidates(branch):
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


def query_files(plans: list[RulePlan], sources: list[tuple[Any, Any]], skip: set[int] = frozenset()) -> dict[str, str]:
    """The diagnostic queries as DRL files, each its own package of at most QUERIES_PER_PACKAGE
    queries (one package of hundreds of queries exceeds the JVM's method size limit), importing
    every declared type and keeping the rule's file's imports and globals."""
    declared = sorted({f"{items.package}.{item.name.rsplit('.', 1)[-1]}" for _src, items in sources if items is not None
                       for item in items.items if item.kind in ("type", "enum")})
    headers = {src.file: (items.package, _PACKAGE.sub("", items.header()))
               for src, items in sources if items is not None}
    chunks: list[tuple[str, list[str]]] = []
    for plan in plans:
        if plan.number in skip or plan.broken:
            continue
        package, header = headers.get(plan.file, ("defaultpkg", ""))
        texts = [f'query "{name}"\n    {body}\nend\n' for name, body in _queries(plan)]
        if not chunks or chunks[-1][0] != plan.file or len(chunks[-1][1]) + len(texts) > QUERIES_PER_PACKAGE:
            chunks.append((plan.file, []))
        chunks[-1][1].extend(texts)
    out = {}
    for n, (fname, texts) in enumerate(chunks, start=1):
        package, header = headers.get(fname, ("defaultpkg", ""))
        imports = "\n".join(f"import {name};" for name in declared if name.rsplit(".", 1)[0] != f"{package}.why{n}")
        out[QUERY_FILE.format(n=n)] = (f"package {package}.why{n};\n{imports}\n{header}\n\n" + "\n".join(texts))
    return out


@dataclass
class Explainer:
    """A version's (or draft's) rules compiled, and its types compiled with the diagnostic queries."""

    plans: list[RulePlan]
    rules: Any  # the rule set compiled (shared with the version's own build)
    queries: Any  # the declarations (rules left out) with the queries


def _broken_rules(errors: list[CompileError], files: dict[str, str], plans: list[RulePlan]) -> set[int]:
    """The rules whose queries the compile errors point at (by the query name above the error's line)."""
    broken: set[int] = set()
    for err in errors:
        text = files.get(err.file)
        if text is None:
            continue
        before = text.split("\n")[:max(err.line, 1)]
        for line in reversed(before):
            match = re.match(r'\s*query "why__(\d+)__', line)
            if match:
                broken.add(int(match.group(1)))
                break
    return broken


def declarations(sources: list[tuple[Any, Any]]) -> dict[str, str]:
    """The rule set's DRL without its rules (types, functions, globals, queries), one file per source:
    the queries run on their own build of these, so the rules are not compiled again for them."""
    return {f"zz_base_{n}.drl": items.blanked(lambda item: item.kind != "rule")
            for n, (_src, items) in enumerate(sources, start=1) if items is not None}


def build(engine: Any, files: dict[str, str]) -> Explainer:
    """Compile ``files`` (shared with their own build) and, apart, their declarations with every
    rule's diagnostic queries. A rule whose queries do not compile (a condition this reader does not
    understand) is left out of the queries and says so."""
    rules = engine.compile_draft(files)
    plans, sources = plan_rules(files)
    base = declarations(sources)
    skip: set[int] = set()
    for _attempt in range(4):
        extra = query_files(plans, sources, skip)
        try:
            return Explainer(plans, rules, engine.compile_draft({**base, **extra}))
        except CompileFailed as failed:
            ours = [e for e in failed.errors if e.file in extra]
            newly = _broken_rules(ours, extra, plans) - skip
            if not newly or len(ours) < len(failed.errors):
                raise
            for plan in plans:
                if plan.number in newly:
                    plan.broken = "its conditions could not be turned into diagnostic queries: " + ours[0].message
            skip |= newly
    raise EngineError("the diagnostic queries of this rule set do not compile")


class ExplainBusy(EngineError):
    """Too many explanations wait in this process (429)."""

    kind = "limit"


class ExplainCache:
    """Explainers by file content (a version, or a draft), built once, kept for the last few."""

    def __init__(self, size: int = CACHE_SIZE) -> None:
        self._size = size
        self._worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="explain")
        self._waiting = threading.BoundedSemaphore(MAX_WAITING)
        self._built: OrderedDict[str, Explainer] = OrderedDict()
        self._lock = threading.Lock()
        self._building: dict[str, threading.Lock] = {}
        self._prebuild: OrderedDict[str, dict[str, str]] = OrderedDict()  # rule set -> its newest live files
        self._draining = False
        self.timings: deque[tuple[float, float]] = deque(maxlen=1000)  # (wall ms, CPU ms) of the last explanations
        self.builds = 0  # explainers built (a test asserts an explanation after a deploy builds none)

    def run(self, engine: Any, files: dict[str, str], facts: list[dict[str, Any]]) -> dict[str, Any]:
        """Explain ``facts`` on ``files``: built (once) and asked on the cache's own long-lived
        thread, one explanation at a time; more than MAX_WAITING waiting is refused (ExplainBusy).

        Why one thread: an explanation's first build compiles hundreds of queries; one at a time
        on a thread of its own, explaining never takes more than one core from serving, and the
        queue in front of it is bounded."""
        if not self._waiting.acquire(blocking=False):
            raise ExplainBusy(f"{MAX_WAITING} explanations are already waiting on this gateway process; try again shortly")
        try:
            return self._worker.submit(self._timed, engine, files, facts).result()
        finally:
            self._waiting.release()

    def _timed(self, engine: Any, files: dict[str, str], facts: list[dict[str, Any]]) -> dict[str, Any]:
        """One explanation on the explain thread, its wall and CPU time kept (``timings``): on a
        loaded machine the wall time says more about the neighbours than about explaining. The
        thread's CPU time includes the JVM's work, which runs on this same thread."""
        explainer = self.get(engine, files)
        wall, cpu = time.perf_counter(), time.thread_time()
        answer = explain(engine, explainer, facts)
        self.timings.append(((time.perf_counter() - wall) * 1000, (time.thread_time() - cpu) * 1000))
        return answer

    def has(self, files: dict[str, str]) -> bool:
        """Whether the explainer of ``files`` is built (an explanation of them compiles nothing)."""
        with self._lock:
            return content_hash(files) in self._built

    def prebuild(self, engine: Any, name: str, files: dict[str, str]) -> None:
        """Build the explainer of ``files`` (rule set ``name``'s new live version) soon, on the
        explain thread, off the serving path: the first explanation of a version then finds its
        queries compiled instead of compiling them (~10 s for the 32 reception rules).

        Bounded: one pending build per rule set (a newer deploy replaces an older one not started
        yet), at most CACHE_SIZE rule sets pending (the oldest dropped: it would leave the cache
        anyway); explanations asked meanwhile wait behind at most the build in progress."""
        with self._lock:
            if content_hash(files) in self._built:
                return
            self._prebuild.pop(name, None)
            self._prebuild[name] = files
            while len(self._prebuild) > self._size:
                self._prebuild.popitem(last=False)
            start, self._draining = not self._draining, True
        if start:
            try:
                self._worker.submit(self._drain, engine)
            except RuntimeError:  # the explain thread is shut down (closing): nothing to prepare for
                with self._lock:
                    self._draining = False

    def _drain(self, engine: Any) -> None:
        """On the explain thread: build the pending explainers, newest deploy of each rule set."""
        while True:
            with self._lock:
                if not self._prebuild:
                    self._draining = False
                    return
                name, files = self._prebuild.popitem(last=False)
            try:
                explainer = self.get(engine, files)
                # one explanation on the rule set's first example (or no facts) loads the queries'
                # classes and warms their code in the JVM: the first real one is then as quick as the next
                examples = warmup.example_fact_sets(files)
                explain(engine, explainer, examples[0] if examples else [])
            except Exception as exc:  # an explanation will build it again and report the error then
                log.warning("explain queries of %s not built in advance: %s", name, exc)

    def close(self) -> None:
        """Stop the explain thread (detached from the JVM first, as a thread that ends should be)
        and forget the built explainers. Builds waiting to be made in advance are dropped (only
        the one in progress is waited for)."""
        with self._lock:
            self._prebuild.clear()

        def detach() -> None:
            import jpype

            if jpype.isJVMStarted() and jpype.java.lang.Thread.isAttached():
                jpype.java.lang.Thread.detach()
        try:
            self._worker.submit(detach).result(timeout=30)
        except Exception:  # closing must go on
            log.debug("explain thread not detached", exc_info=True)
        self._worker.shutdown(wait=True)
        with self._lock:
            self._built.clear()

    def get(self, engine: Any, files: dict[str, str]) -> Explainer:
        key = content_hash(files)
        with self._lock:
            if key in self._built:
                self._built.move_to_end(key)
                return self._built[key]
            lock = self._building.setdefault(key, threading.Lock())
        with lock:  # one build per text, however many ask at once
            with self._lock:
                if key in self._built:
                    return self._built[key]
            explainer = build(engine, files)
            with self._lock:
                self.builds += 1
                self._built[key] = explainer
                while len(self._built) > self._size:
                    self._built.popitem(last=False)
                self._building.pop(key, None)
            return explainer


# --------------------------------------------------------------------------- explaining


def _value(fact: Any, path: str) -> Any:
    value = fact
    for part in path.split("."):
        if not isinstance(value, dict):
            return None
        value = value.get(part)
    return value


def _show(value: Any) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def _describe(fact: Any) -> str:
    """A fact in a few words: ``Guest "g1"`` when it has an id or name, else ``Group(kind="pair", size=2)``."""
    if isinstance(fact, dict):
        kind = fact.get("type", "fact")
        ident = fact.get("id") or fact.get("name")
        if ident is not None:
            return f"{kind} {_show(ident)}"
        fields = [f"{k}={_show(v)}" for k, v in fact.items() if k != "type" and not isinstance(v, (dict, list))][:3]
        return f"{kind}({', '.join(fields)})"
    return _show(fact)


def _wants(constraint: str) -> str:
    equals = _EQUALS.match(constraint)
    return equals.group(1).strip() if equals else constraint


class ThrowawaySession:
    """A Java ``Session`` used for one explanation and disposed: insert, fire, query.

    Not a :class:`gateway.engine.session.StatefulSession`: that one is made to live long (it shares
    buffers with the JVM for the stream path, keeps a lock, follows deploys); this one needs none
    of it."""

    def __init__(self, java: Any, fire_limit: int, max_facts: int) -> None:
        self._java = java
        self._fire_limit = fire_limit
        self._max_facts = max_facts

    def insert(self, facts: list[dict[str, Any]]) -> None:
        _checked(self._java.insert(encode_facts(facts, self._max_facts)))

    def fire(self, return_facts: bool = False) -> FireResult:
        return decode_result(str(self._java.fire(self._fire_limit, return_facts)), "(explain)", 0, 0.0)

    def query(self, name: str) -> dict[str, Any]:
        return _checked(self._java.query(str(name), "[]"))

    def queries(self, names: list[str], max_rows: int) -> dict[str, list[dict[str, Any]]]:
        """Several queries in one JVM call, at most ``max_rows`` rows each."""
        return _checked(self._java.queries(orjson.dumps(names).decode(), int(max_rows)))["results"]

    def close(self) -> None:
        self._java.dispose()


def _checked(answer: Any) -> dict[str, Any]:
    data = orjson.loads(str(answer))
    if not data.get("ok"):
        raise FactError(data.get("errors", []), data.get("errorCount"))
    return data


class Run:
    """One explanation's session: the facts inserted and fired, then queried."""

    def __init__(self, session: Any) -> None:
        self.session = session
        self._rows: dict[str, list[dict[str, Any]]] = {}

    def rows(self, name: str) -> list[dict[str, Any]]:
        if name not in self._rows:
            self._rows[name] = self.session.query(name)["rows"]
        return self._rows[name]

    def prefetch(self, names: list[str]) -> None:
        """Ask ``names`` at once (one JVM call): what explaining the rules that did not fire needs.
        Rows beyond MAX_SHOWN are never shown, so they are not fetched."""
        if names:
            self._rows.update(self.session.queries(names, MAX_SHOWN))

    @property
    def fetched(self) -> set[str]:
        return set(self._rows)


def _closest(run: Run, cond: Condition, name: Callable[[int], str]) -> tuple[Any, int]:
    """The candidate fact of ``cond`` that passes the most of its constraints in order, and how
    many it passes (-1: there is no candidate at all); ``name(j)``: the query with j constraints."""
    best, passed = None, -1
    for j in range(0, len(cond.constraints) + 1):
        rows = run.rows(name(j))
        if not rows:
            break
        best, passed = rows[0].get(FACT), j
    return best, passed


def _why_pattern(run: Run, plan: RulePlan, k: int, cond: Condition,
                 name: Callable[[int], str] | None = None) -> dict[str, Any]:
    fact, passed = _closest(run, cond, name or (lambda j: plan.candidate_query(k, j)))
    out: dict[str, Any] = {"constraint": None, "closest": None}
    source = f" {cond.suffix}" if cond.kind == "from" else ""
    out["score"] = -1.0
    if passed < 0 or cond.type is None:
        if cond.kind == "accumulate":
            out["reason"] = f"the accumulate gives no value ({cond.suffix})"
        else:
            out["reason"] = f"there is no {cond.type} fact{source}"
        return out
    if passed >= len(cond.constraints):  # every constraint holds for some fact: an earlier binding is what fails
        out["reason"] = f"a {cond.type} matches its own constraints, but not together with the conditions before it"
        out["closest"] = {"fact": fact}
        out["score"] = 1.0
        return out
    failing = cond.constraints[passed]
    field_match = _FIELD.match(failing)
    field_name = field_match.group(1) if field_match else None
    value = _value(fact, field_name) if field_name and isinstance(fact, dict) else fact
    out["constraint"] = failing
    out["closest"] = {"fact": fact, "passed": passed, "of": len(cond.constraints), "field": field_name,
                      "value": value}
    out["score"] = passed / len(cond.constraints)
    if cond.kind == "accumulate":
        out["reason"] = f"the accumulated value is {_show(fact)}, the rule wants {failing}"
    elif field_name and isinstance(fact, dict) and field_name in fact or "." in (field_name or ""):
        shown = field_name if field_name and "." not in field_name else field_name
        out["reason"] = f"{shown} is {_show(value)}, the rule wants {_wants(failing)} ({_describe(fact)} came closest)"
    else:
        out["reason"] = f"{_describe(fact)} came closest; it fails {failing}"
    if cond.kind == "exists":
        out["reason"] = f"no {cond.type} fact{source} exists that matches; " + out["reason"]
    elif cond.kind == "from":
        out["reason"] = f"no item {cond.suffix} matches; " + out["reason"]
    return out


def _why_alternative(run: Run, plan: RulePlan, k: int, branch: Condition) -> dict[str, Any]:
    """How close one alternative of an "or" came: ``score`` is the share of its constraints the
    closest fact passes (1: it holds on its own, -1: nothing to match at all)."""
    out: dict[str, Any] = {"index": branch.index, "drl": branch.drl}
    if branch.kind == "not":
        blockers = [r.get(FACT) for r in run.rows(plan.branch_query(k, branch.index, len(branch.constraints)))]
        return {**out, "score": -1.0, "exists": blockers[:MAX_SHOWN],
                "reason": f"{_describe(blockers[0])} exists" if blockers else f"a {branch.type} fact exists"}
    if _has_candidates(branch):
        why = _why_pattern(run, plan, k, branch, lambda j: plan.branch_query(k, branch.index, j))
        return {**out, **why}
    holds = bool(run.rows(plan.branch_query(k, branch.index)))
    return {**out, "score": 1.0 if holds else -1.0,
            "reason": "it holds on its own, but not with the conditions before it" if holds else "it does not hold"}


def _why_or(run: Run, plan: RulePlan, k: int, cond: Condition) -> dict[str, Any]:
    """Which alternative came closest, and what stopped it; every alternative's reason besides."""
    alternatives = [_why_alternative(run, plan, k, b) for b in cond.branches]
    best = max(alternatives, key=lambda a: a["score"])
    for a in alternatives:
        a.pop("score")
    return {"constraint": best.get("constraint"), "closest": best.get("closest"), "alternatives": alternatives,
            "closest_alternative": best["index"],
            "reason": f"none of its {len(alternatives)} alternatives holds; the closest is alternative "
                      f"{best['index']} ({best['drl']}): {best['reason']}"}


def _why_forall(run: Run, plan: RulePlan, k: int, cond: Condition) -> dict[str, Any]:
    """The element that breaks the forall, and what it lacks (the constraint it fails, for a
    forall of one pattern; the patterns it has no match in, for more)."""
    first, rest = cond.branches[0], cond.branches[1:]
    key = first.binding if rest and first.binding else FACT
    violators = [r.get(key) for r in run.rows(plan.violators_query(k))]
    if not violators:
        return {"constraint": None, "reason": f"the forall ({cond.drl}) does not hold with the conditions before it"}
    fact = violators[0]
    out: dict[str, Any] = {"violating": violators[:MAX_SHOWN]}
    if rest:
        wanted = " and ".join(r.drl for r in rest)
        return {**out, "constraint": wanted,
                "reason": f"{_describe(fact)} matches {first.drl} but has no {wanted}: the rule wants it for every "
                          f"such {first.type} ({len(violators)} without)"}
    for j, constraint in enumerate(first.constraints):
        if any(r.get(FACT) == fact for r in run.rows(plan.violators_query(k, j))):
            field_match = _FIELD.match(constraint)
            field_name = field_match.group(1) if field_match else None
            if field_name and isinstance(fact, dict) and field_name in fact:
                detail = f"{field_name} is {_show(fact[field_name])}, the rule wants {_wants(constraint)}"
            else:
                detail = f"it fails {constraint}"
            return {**out, "constraint": constraint,
                    "reason": f"{_describe(fact)} breaks the forall: {detail} for every {first.type}"}
    return {**out, "constraint": None, "reason": f"{_describe(fact)} does not match {first.drl}"}


def prefetch(run: Run, plans: list[RulePlan]) -> None:
    """Ask, in two JVM calls, the queries explaining ``plans`` (the rules that did not fire) will
    read: every prefix ``C1 … Ck``, then the candidate queries of each rule's first failing
    condition. One call per query cost more than the queries (~95 calls for the reception set)."""
    run.prefetch([plan.prefix_query(k) for plan in plans for k in range(1, len(plan.conditions) + 1)])
    second = []
    for plan in plans:
        k = next((k for k in range(1, len(plan.conditions) + 1) if not run.rows(plan.prefix_query(k))), None)
        if k is not None:
            second.extend(plan.condition_names(k))
    run.prefetch([name for name in second if name not in run.fetched])


def explain_rule(run: Run, plan: RulePlan, fired: list[list[Any]]) -> dict[str, Any]:
    """What one rule did: fired with its matches, or the condition that stopped it and why."""
    base: dict[str, Any] = {"rule": plan.name, "file": plan.file, "line": plan.line}
    if fired:
        return {**base, "fired": True, "matches": fired}
    if plan.broken:
        return {**base, "fired": False, "reason": f"cannot be explained: {plan.broken}"}
    for k, cond in enumerate(plan.conditions, start=1):
        if run.rows(plan.prefix_query(k)):
            continue
        out = {**base, "fired": False, "condition": {**cond.where(), "of": len(plan.conditions)}}
        if cond.kind == "not":
            blockers = [r.get(FACT) for r in run.rows(plan.candidate_query(k, len(cond.constraints)))]
            out.update(constraint=None, exists=blockers[:MAX_SHOWN],
                       reason=f"{_describe(blockers[0])} exists, and the rule wants no such {cond.type}"
                       if blockers else f"a {cond.type} fact exists, and the rule wants none")
        elif cond.kind in ("pattern", "exists", "from", "accumulate"):
            out.update(_why_pattern(run, plan, k, cond))
            out.pop("score", None)
        elif cond.kind == "or":
            out.update(_why_or(run, plan, k, cond))
        elif cond.kind == "forall":
            out.update(_why_forall(run, plan, k, cond))
        elif cond.kind == "eval":
            out.update(constraint=cond.drl, reason=f"{cond.drl} is false")
        else:
            out.update(constraint=None, reason=f"condition {k} ({cond.drl}) does not hold")
        return out
    return {**base, "fired": False, "condition": None,
            "reason": "all its conditions hold, but it did not fire: its agenda group had no focus, a rule of its "
                      "activation group fired first, no-loop/lock-on-active stopped it, or the fire limit was reached"}


def explain(engine: Any, explainer: Explainer, facts: list[dict[str, Any]]) -> dict[str, Any]:
    """Fire ``facts`` on the rules in a throwaway session, then ask the diagnostic queries on the
    facts as the rules left them (another throwaway session) and explain every rule."""
    session = engine.explain_session(explainer.rules)
    try:
        session.insert(facts)
        result = session.fire(return_facts=True)
    finally:
        session.close()
    matches: dict[str, list[list[Any]]] = {}
    for entry in result.fired:
        matches.setdefault(entry["rule"], []).append(entry.get("facts") or [])
    queries = engine.explain_session(explainer.queries)
    try:
        queries.insert(result.facts)
        run = Run(queries)
        prefetch(run, [plan for plan in explainer.plans if plan.name not in matches and not plan.broken])
        rules = [explain_rule(run, plan, matches.get(plan.name, [])) for plan in explainer.plans]
    finally:
        queries.close()
    return {"fired": [entry["rule"] for entry in result.fired], "actions": result.actions, "rules": rules}
