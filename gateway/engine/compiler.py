"""Compiling a rule set with Drools' executable model, and turning every failure into
``CompileError(file, line, column, message)``.

This is the thin JVM adapter of the engine. The order of checks matters for good messages:

1. the ``.dsl`` mapping files are parsed on their own (a broken mapping line names its line);
2. each ``.dslr`` is expanded with the DSL files it names (``expander x.dsl``): a sentence that
   matches no mapping is reported at its own line; each decision table (``.csv``, ``.xlsx``) is
   converted to DRL (:mod:`gateway.engine.decision_table`), its problems named by sheet and cell;
3. every DRL text (written or expanded) goes through Drools' DRL parser: syntax errors with line
   and column;
4. only then the executable-model build, whose errors (unknown types and fields, Java errors in
   then-parts) come with poor positions — we locate them in the source text.

A successful build gives a :class:`~gateway.engine.build.CompiledRuleSet`: the KieBase wrapped by
the Java ``Runner``.

Builds are incremental (:mod:`gateway.engine.incremental`): the set is compiled in units whose
classes are cached by content (memory and disk), and a new version compiles only the rules that
changed. :func:`gateway.engine.build.build_unit` is the one place a DRL text meets Drools'
executable-model builder; the types both modules hand around live there too.
"""

from __future__ import annotations

import difflib
import itertools
import logging
import re
import threading
from collections import Counter, OrderedDict
from typing import Any

from gateway.base import jvm
from gateway.engine import decision_table, drl_items, incremental, plain_rules, rule_dates, scenario_files
from gateway.engine.build import (
    DEFAULT_OPTIONS,
    CompiledRuleSet,
    CompileOptions,
    Progress,
    Source,
    java_classes,
    memory_error,
    oom_types,
    sorted_errors,
)
from gateway.engine.errors import CompileError, CompileFailed, InvalidRuleSet
from gateway.engine.ruleset import check_files, content_hash, is_table_file

log = logging.getLogger(__name__)
_build_counter = itertools.count(1)
_compile_lock = threading.RLock()
_EXPANDER_LINE = re.compile(r"^\s*expander\s+(\S+?)\s*;?\s*$", re.MULTILINE)
_LINE_COL = re.compile(r"[Ll]ine (\d+):(\d+)")


def _align_lines(expanded: str, original: str) -> list[int]:
    """Maps each expanded line to its .dslr line, anchored on lines the expander left unchanged
    (rule/when/then/end, comments, plain DRL); lines in between keep their order."""
    exp = [line.strip() for line in expanded.split("\n")]
    src = [line.strip() for line in original.split("\n")]
    mapping = [0] * len(exp)
    anchors: list[tuple[int, int]] = []
    for block in difflib.SequenceMatcher(None, exp, src, autojunk=False).get_matching_blocks():
        anchors.extend((block.a + k, block.b + k) for k in range(block.size))
    anchor_iter = iter(anchors + [(len(exp), len(src))])
    prev_a, prev_b = -1, -1
    next_a, next_b = next(anchor_iter)
    for i in range(len(exp)):
        while i > next_a:
            prev_a, prev_b = next_a, next_b
            next_a, next_b = next(anchor_iter)
        if i == next_a:
            mapping[i] = next_b + 1
        else:
            mapping[i] = min(prev_b + (i - prev_a), next_b - 1) + 1 if prev_a >= 0 else min(i, next_b - 1) + 1
    return mapping


# --------------------------------------------------------------------------- DSL


def _parse_dsl_files(files: dict[str, str]) -> tuple[dict[str, Any], list[CompileError]]:
    """Each .dsl file -> its Java DSLMapping; errors name the mapping line."""
    j = java_classes()
    mappings: dict[str, Any] = {}
    errors: list[CompileError] = []
    for fname, text in files.items():
        if not fname.endswith(".dsl"):
            continue
        dsl = j["DslFile"]()
        ok = dsl.parseAndLoad(j["StringReader"](text))
        if not ok or dsl.getErrors().size() > 0:
            for err in dsl.getErrors():
                line, col = _dsl_error_position(err)
                message = str(err.getMessage()).split("\n")[0]
                errors.append(CompileError(fname, line, col, f"broken DSL mapping: {message}"))
            if not errors:
                errors.append(CompileError(fname, 0, 0, "the DSL file could not be read"))
        else:
            mappings[fname] = dsl.getMapping()
    return mappings, _dedupe_dsl_errors(errors, files)


def _dsl_error_position(err: Any) -> tuple[int, int]:
    try:
        row, col = int(err.getRow()), int(err.getCol())
        return (max(row, 0), max(col, 0) + (1 if row > 0 else 0))
    except AttributeError:
        lines = list(err.getLines() or [])
        return (int(lines[0]) if lines and lines[0] > 0 else 0, 0)


def _dedupe_dsl_errors(errors: list[CompileError], files: dict[str, str]) -> list[CompileError]:
    """Drools reports a broken mapping twice (once with a line, once as a regex error without):
    keep the positioned one and fold the detail of the other into it."""
    positioned = [e for e in errors if e.line > 0]
    unpositioned = [e for e in errors if e.line <= 0]
    if positioned and unpositioned:
        first = positioned[0]
        detail = unpositioned[0].message.replace("broken DSL mapping: ", "")
        positioned[0] = CompileError(first.file, first.line, first.column, f"{first.message} ({detail})")
        return positioned
    return errors


def _expand_dslr(
    fname: str, text: str, mappings: dict[str, Any], files: dict[str, str]
) -> tuple[str | None, list[CompileError]]:
    """Expands one .dslr to DRL with the DSL files it names (or all of them if it names none)."""
    j = java_classes()
    named = _EXPANDER_LINE.findall(text)
    errors: list[CompileError] = []
    chosen: list[Any] = []
    if named:
        for dsl_name in named:
            if dsl_name in mappings:
                chosen.append(mappings[dsl_name])
            elif dsl_name in files:
                return None, []  # the DSL file itself is broken: its own errors say where
            else:
                line = _line_of(text, re.compile(r"^\s*expander\s+" + re.escape(dsl_name), re.MULTILINE))
                errors.append(CompileError(fname, line, 1, f"expander '{dsl_name}' not found in this rule set"))
    else:
        chosen = list(mappings.values())
    if errors:
        return None, errors
    if not chosen:
        return None, [CompileError(fname, 1, 1, "a .dslr file needs a DSL: add a .dsl file and 'expander <name>.dsl'")]
    expander = j["Expander"]()
    for mapping in chosen:
        expander.addDSLMapping(mapping)
    expanded = str(expander.expand(text))
    lines = text.split("\n")
    for err in expander.getErrors():
        line = int(err.getLine())
        source_line = lines[line - 1] if 0 < line <= len(lines) else ""
        column = len(source_line) - len(source_line.lstrip()) + 1 if source_line else 0
        message = re.sub(r"^\[\d+\]\s*", "", str(err.getMessage())).strip()
        if message.startswith("Unable to expand"):
            message = f"no DSL sentence matches: '{source_line.strip()}'"
        elif message.startswith("No mapping entries for expanding"):
            continue  # always paired with an "Unable to expand" for the same line
        errors.append(CompileError(fname, line, column, message))
    return expanded, errors


def _line_of(text: str, pattern: re.Pattern[str]) -> int:
    match = pattern.search(text)
    return text.count("\n", 0, match.start()) + 1 if match else 0


def expand(files: dict[str, str]) -> dict[str, str]:
    """The DRL each .dslr file expands to (for the workbench's preview and ``/expand``)."""
    check_files(files)
    with _compile_lock:
        mappings, errors = _parse_dsl_files(files)
        out: dict[str, str] = {}
        for fname, text in files.items():
            if fname.endswith(".dslr"):
                drl, errs = _expand_dslr(fname, text, mappings, files)
                errors.extend(errs)
                if drl is not None:
                    out[fname] = drl
            elif is_table_file(fname):  # a decision table's DRL shows in the same preview
                table = decision_table.convert(fname, text)
                errors.extend(table.errors)
                if table.drl is not None:
                    out[fname] = table.drl
    if errors:
        raise CompileFailed(errors)
    return out


# --------------------------------------------------------------------------- the rule policy


def policy_errors(files: dict[str, str], rule_policy: Any) -> list[CompileError]:
    """What ``rule_policy`` (a :class:`gateway.engine.policy.RulePolicy`) refuses in the expanded DRL
    of every file (written, from a ``.dslr``, from a decision table), located like compile errors:
    a ``.dslr`` line, a table's cell. Nothing is compiled here: a set that does not even expand
    gets [] (its compile then fails on those errors before building anything)."""

    try:
        check_files(files)
    except InvalidRuleSet:
        return []
    dsl_key = content_hash({f: t for f, t in files.items() if f.endswith(".dsl")})
    if all((f, t, dsl_key) in _expansions for f, t in files.items() if f.endswith(".dslr")):
        sources, _, errors = _sources(files)  # no JVM needed: a build in progress does not hold this up
    else:
        with _compile_lock:
            sources, _, errors = _sources(files)
    if errors:
        return []
    by_file = {s.file: s for s in sources}
    found = [CompileError(fname, by_file[fname].source_line(v.line), v.column, v.message)
             for fname, violations in rule_policy.check((s.file, s.drl) for s in sources).items()
             for v in violations]
    return sorted_errors(_in_tables(found, sources))


# --------------------------------------------------------------------------- DRL syntax


def _parse(source: Source) -> tuple[list[CompileError], str | None]:
    """Syntax errors of one DRL text, and (when there are none) its top-level items as
    ``Units.describe`` JSON, for the incremental build to split it."""
    j = java_classes()
    parser = j["DrlParser"]()
    try:
        descr = parser.parse(False, source.drl)
    except Exception as exc:  # DroolsParserException: report it with what we know
        return [CompileError(source.file, 0, 0, f"cannot parse: {exc}")], None
    errors: list[CompileError] = []
    for err in parser.getErrors():
        message = str(err.getMessage())
        line, col = _parser_position(err, message)
        if "Parser returned a null Package" in message:
            continue
        errors.append(CompileError(source.file, source.source_line(line), col, _clean_parser_message(message)))
    if errors or descr is None:
        return errors, None
    try:
        return [], str(jvm.helper_class("Units").describe(descr))
    except Exception:  # an item the splitter does not know: the set is built in one unit
        log.debug("could not describe %s", source.file, exc_info=True)
        return [], None


def rule_sources(files: dict[str, str]) -> list[tuple[Source, drl_items.SourceItems | None]]:
    """Every DRL text of ``files`` (written, expanded from a .dslr, generated from a decision
    table) with its items, for tools that read rules (explain); a text whose items cannot be placed
    comes with None. Compile errors raise CompileFailed."""
    check_files(files)
    with _compile_lock:
        sources, _expanded, errors = _sources(files)
        if errors:
            raise CompileFailed(errors)
        out: list[tuple[Source, drl_items.SourceItems | None]] = []
        for source in sources:
            problems, described = _parse(source)
            if problems:
                raise CompileFailed(problems)
            out.append((source, drl_items.parse_items(source.file, source.drl, described) if described else None))
        return out



def plain_split(files: dict[str, str]) -> Counter[str]:
    """How many rules of ``files`` are of the plain shapes (key ``"plain"``: built without
    generating Java) and, for the others, why each goes to Drools' compiler
    (:func:`plain_rules.why_not`). Why: a rule base's cold build time is decided by this split; the
    growth bench reports it for each generator. (The Java side may still refuse a described rule,
    e.g. a literal of another type than its field: the build's stats count those.)"""
    return plain_rules.reasons([items for _, items in rule_sources(files) if items is not None])

def _parser_position(err: Any, message: str) -> tuple[int, int]:
    match = _LINE_COL.search(message)
    if match:
        return int(match.group(1)), int(match.group(2)) + 1
    try:
        row, col = int(err.getRow()), int(err.getCol())
        if row > 0:
            return row, col + 1
    except AttributeError:
        pass
    return 0, 0


def _clean_parser_message(message: str) -> str:
    message = re.sub(r"^\[ERR \d+\]\s*", "", message)
    message = _LINE_COL.sub("", message, count=1).strip()
    if re.search(r"mismatched input '(rule|query|declare|function)'", message) or "mismatched input '<EOF>'" in message:
        message += " (is an 'end' missing before this point?)"
    return message


# --------------------------------------------------------------------------- build


def _sources(files: dict[str, str]) -> tuple[list[Source], dict[str, str], list[CompileError]]:
    dsl_key = content_hash({f: t for f, t in files.items() if f.endswith(".dsl")})
    if any(f.endswith(".dslr") and (f, files[f], dsl_key) not in _expansions for f in files):
        mappings, errors = _parse_dsl_files(files)
    else:  # every .dslr expanded before with these very mappings
        mappings, errors = {}, []
    sources: list[Source] = []
    expanded: dict[str, str] = {}
    for fname, text in sorted(files.items()):
        if fname.endswith(".drl"):
            sources.append(Source(fname, text))
        elif fname.endswith(".dslr"):
            key = (fname, text, dsl_key)
            done = _expansions.get(key)
            if done is None:
                drl, errs = _expand_dslr(fname, text, mappings, files)
                line_map = _align_lines(drl, text) if drl is not None and not errs else None
                done = (drl, errs, line_map)
                if not errors:  # an expansion next to a broken mapping is not worth keeping
                    _remember(_expansions, key, done, 64)
            drl, errs, line_map = done
            errors.extend(errs)
            if drl is not None:
                expanded[fname] = drl
            if drl is not None and not errs:  # a half-expanded text would only add confusing errors
                sources.append(Source(fname, drl, line_map))
        elif is_table_file(fname):
            table = decision_table.convert(fname, text)
            errors.extend(table.errors)
            if table.drl is not None:
                expanded[fname] = table.drl
                if not table.errors:
                    sources.append(Source(fname, table.drl, table=table))
    return sources, expanded, errors


def _in_tables(errors: list[CompileError], sources: list[Source]) -> list[CompileError]:
    """Errors found in a decision table's generated DRL, moved to the table's cells."""
    tables = {s.file: s.table for s in sources if s.table is not None}
    if not tables:
        return errors
    return [tables[e.file].locate(e) if e.file in tables else e for e in errors]


# Expansions and parses of unchanged texts are reused: a one-rule edit re-reads only its file.
_expansions: "OrderedDict[tuple[str, str, str], tuple[str | None, list[CompileError], list[int] | None]]" = OrderedDict()
_parses: "OrderedDict[tuple[str, str, tuple[int, ...] | None], tuple[list[CompileError], str | None]]" = OrderedDict()


def _remember(cache: "OrderedDict[Any, Any]", key: Any, value: Any, size: int) -> None:
    cache[key] = value
    cache.move_to_end(key)
    while len(cache) > size:
        cache.popitem(last=False)


def _parse_cached(source: Source) -> tuple[list[CompileError], str | None]:
    key = (source.file, source.drl, tuple(source.line_map) if source.line_map is not None else None)
    done = _parses.get(key)
    if done is None:
        done = _parse(source)
        _remember(_parses, key, done, 256)
    else:
        _parses.move_to_end(key)
    return done


_cache: "OrderedDict[str, CompiledRuleSet]" = OrderedDict()
CACHE_SIZE = 16
CACHE_MAX_RULES = 40_000  # a 10,000-rule KieBase holds ~100 MB of heap: keep a few, not sixteen


stats = {"compiles": 0}  # builds compile_cached did not find in its cache (tests assert "no compile" with it)


def compile_cached(
    files: dict[str, str],
    label: str = "ruleset",
    options: CompileOptions | None = None,
    on_progress: Progress | None = None,
) -> CompiledRuleSet:
    """Like :func:`compile_files`, reusing an earlier build of identical files.

    A compiled rule set is immutable, so sharing it between versions, engines and drafts is safe;
    it makes "try it" in the workbench, validate-then-deploy and rollbacks cost one build only.
    """
    key = content_hash(files)
    with _compile_lock:
        cached = _cache.get(key)
        if cached is not None:
            _cache.move_to_end(key)
            return cached
        compiled = compile_files(files, label, options, on_progress)
        stats["compiles"] += 1
        _cache[key] = compiled
        while len(_cache) > CACHE_SIZE or (
            len(_cache) > 1 and sum(c.rule_count for c in _cache.values()) > CACHE_MAX_RULES
        ):
            _cache.popitem(last=False)
        return compiled


def compile_files(
    files: dict[str, str],
    label: str = "ruleset",
    options: CompileOptions | None = None,
    on_progress: Progress | None = None,
) -> CompiledRuleSet:
    """Compiles a rule set; raises CompileFailed with positioned errors, CompileResourceError when
    the JVM runs out of memory or the compile time limit passes.

    ``on_progress(done, total, stage)`` is called from this thread as the build goes: stages
    "parse" (files), "compile" (rules compiled of those that need it), "load" (units), "assemble".
    """

    options = options or DEFAULT_OPTIONS
    try:
        check_files(files)
    except InvalidRuleSet as bad:
        raise CompileFailed(bad.errors or [CompileError("", 0, 0, str(bad))]) from None
    with _compile_lock:
        try:
            reused = incremental.build_from_plan(files, options, on_progress)
            if reused is not None:
                return reused
            sources, expanded, errors = _sources(files)
            errors.extend(scenario_files.format_errors(files))  # a malformed tests/*.yaml is refused like bad rules
            described: list[str | None] = []
            for n, source in enumerate(sources):
                errs, info = _parse_cached(source)
                errors.extend(errs)
                described.append(info)
                if on_progress is not None:
                    incremental._progress(on_progress, n + 1, len(sources), "parse")
            errors.extend(rule_dates.errors(sources))  # a bad date fails here, not when its unit loads
            if errors:
                raise CompileFailed(sorted_errors(_in_tables(errors, sources)))
            try:
                return incremental.build(files, sources, described, expanded, label, options, on_progress)
            except CompileFailed as failed:
                raise CompileFailed(sorted_errors(_in_tables(failed.errors, sources))) from None
        except oom_types() as exc:  # anywhere on the way: the author's text is not to blame
            raise memory_error() from exc


_WARM_DRL = """package org.printeps.warmup;
import org.printeps.gateway.Actions;
global Actions actions;
declare Item id: String size: int price: double kind: String end
rule "range {n}" when $i: Item(kind == "a", price >= {n}.0, price < {m}.0) then actions.say("w", $i.getId()); end
rule "equal {n}" when Item(kind == "b{n}", size == {n}) then actions.say("w", "{n}"); end
rule "join {n}" when $a: Item(kind == "a") $b: Item(kind == "b", size > $a.size) then actions.say("w", $b.getId()); end
rule "sum {n}" when $a: Item(kind == "a") accumulate(Item(kind == "c", $p: price); $t: sum($p); $t > {n}.0)
then actions.say("w", "sum"); end
"""


def warm_builder(rounds: int = 2) -> None:
    """Compiles a small, never-cached rule set ``rounds`` times, so the JIT has compiled Drools'
    builder (DRL parser, code generator, Java compiler) before an author's first edit: a one-rule
    edit costs ~0.1 s warm and seconds in a cold JVM."""
    import random

    options = CompileOptions(disk_cache=False, workers=1, timeout_s=None)
    for _ in range(rounds):
        n = random.randrange(1_000_000)
        text = _WARM_DRL.replace("{n}", str(n)).replace("{m}", str(n + 10))
        compile_files({"warmup.drl": text}, "warmup", options)


