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

A successful build gives a :class:`CompiledRuleSet`: the KieBase wrapped by the Java ``Runner``.

Builds are incremental (:mod:`gateway.engine.incremental`): the set is compiled in units whose
classes are cached by content (memory and disk), and a new version compiles only the rules that
changed. :func:`build_unit` is the one place a DRL text meets Drools' executable-model builder.
"""

from __future__ import annotations

import difflib
import itertools
import logging
import re
import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Any, Callable

from gateway import jvm
from gateway.engine import decision_table, drl_items, scenarios
from gateway.engine.errors import CompileError, CompileFailed, CompileResourceError, says_out_of_memory
from gateway.engine.ruleset import check_files, content_hash, is_table_file

log = logging.getLogger(__name__)
_build_counter = itertools.count(1)
_compile_lock = threading.RLock()
_EXPANDER_LINE = re.compile(r"^\s*expander\s+(\S+?)\s*;?\s*$", re.MULTILINE)
_LINE_COL = re.compile(r"[Ll]ine (\d+):(\d+)")


@dataclass
class CompiledRuleSet:
    """A compiled, ready-to-fire rule set (immutable; safe to share between threads)."""

    hash: str
    runner: Any  # org.printeps.gateway.Runner
    container: Any  # None since builds assemble the KieBase from units (was the KieContainer)
    rule_count: int
    types: dict[str, dict[str, str]]
    type_names: dict[str, str]
    expanded: dict[str, str] = field(default_factory=dict)
    rule_names: list[str] = field(default_factory=list)
    kbase: Any = None  # org.kie.api.KieBase (the runner holds it too)
    plan: dict[str, Any] = field(default_factory=dict)  # which cached units it was assembled from
    stats: Any = None  # incremental.BuildStats: what the build compiled and reused, and how long it took
    warmed: bool = False  # set by warmup.warm once its classes are loaded and its paths exercised
    warm_stats: Any = None  # warmup.WarmStats of that warm-up (None: not warmed)
    unit_cache: Any = field(default=None, repr=False)  # the UnitCache holding its units (for export)


@dataclass(frozen=True)
class CompileOptions:
    """How rule sets are built (from ``EngineSettings``; the defaults suit a gateway)."""

    incremental: bool = True  # False: one unit for the whole set, no unit cache (the classic build)
    workers: int = 2  # threads compiling units at once
    timeout_s: float | None = 600.0  # compile time limit (CompileResourceError beyond)
    disk_cache: bool = True  # keep compiled units on disk, shared by processes
    cache_dir: str | None = None  # default: $PRINTEPS_CACHE_DIR or ~/.cache/printeps, + /rule-units
    memory_cache_mb: int = 256  # compiled units kept in memory (zipped class bytes)
    disk_cache_mb: int = 2048
    plain_rules: bool = True  # build rules of the plain shapes at run time (gateway.engine.plain_rules)

    @classmethod
    def from_settings(cls, engine_settings: Any) -> "CompileOptions":
        """Options from ``settings.engine`` (any object with the same attribute names)."""
        def pick(name: str, default: Any) -> Any:
            return getattr(engine_settings, f"compile_{name}", default)

        return cls(
            incremental=pick("incremental", True),
            workers=max(1, int(pick("workers", 2))),
            timeout_s=pick("timeout_s", 600.0) or None,
            disk_cache=pick("disk_cache", True),
            cache_dir=pick("cache_dir", None),
            memory_cache_mb=int(pick("memory_cache_mb", 256)),
            disk_cache_mb=int(pick("disk_cache_mb", 2048)),
            plain_rules=pick("plain_rules", True),
        )


DEFAULT_OPTIONS = CompileOptions()
Progress = Callable[[int, int, str], None]


@dataclass
class _Source:
    """A DRL text to compile and the file it came from (a .drl, or the .dslr it expands).

    ``line_map[i]`` is the source line of DRL line ``i + 1``: the DSL expander folds ``- ``
    continuation lines into the line above, so an expanded text is shorter than its ``.dslr``.
    """

    file: str
    drl: str
    line_map: list[int] | None = None
    table: decision_table.ConvertedTable | None = None  # a decision table: errors go to its cells

    def source_line(self, line: int) -> int:
        if self.line_map is None or line <= 0:
            return line
        return self.line_map[min(line, len(self.line_map)) - 1]


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


def _java():
    """The Java classes this module uses (resolved once the JVM runs). Drools' own classes (the
    parsers, the executable model's project type) come through ``DroolsInternals``, the one seam
    to Drools' implementation (docs/architecture.md, "The Drools seam")."""
    jvm.start()
    import jpype

    drools = jvm.helper_class("DroolsInternals")
    return {
        "KieServices": jpype.JClass("org.kie.api.KieServices"),
        "ExecModel": drools.executableModelProject(),
        "DrlParser": drools.newDrlParser,
        "DslFile": drools.newDslMappingFile,
        "Expander": drools.newDslExpander,
        "StringReader": jpype.JClass("java.io.StringReader"),
        "Runner": jpype.JClass("org.printeps.gateway.Runner"),
        "CompilationErrors": jpype.JClass("org.kie.api.builder.CompilationErrorsException"),
    }


_J: dict[str, Any] | None = None


def _j() -> dict[str, Any]:
    global _J
    if _J is None:
        _J = _java()
    return _J


# --------------------------------------------------------------------------- DSL


def _parse_dsl_files(files: dict[str, str]) -> tuple[dict[str, Any], list[CompileError]]:
    """Each .dsl file -> its Java DSLMapping; errors name the mapping line."""
    j = _j()
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
    j = _j()
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
    from gateway.engine.errors import InvalidRuleSet

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
    return _sorted(_in_tables(found, sources))


# --------------------------------------------------------------------------- DRL syntax


def _parse(source: _Source) -> tuple[list[CompileError], str | None]:
    """Syntax errors of one DRL text, and (when there are none) its top-level items as
    ``Units.describe`` JSON, for the incremental build to split it."""
    j = _j()
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


def rule_sources(files: dict[str, str]) -> list[tuple[_Source, drl_items.SourceItems | None]]:
    """Every DRL text of ``files`` (written, expanded from a .dslr, generated from a decision
    table) with its items, for tools that read rules (explain); a text whose items cannot be placed
    comes with None. Compile errors raise CompileFailed."""
    check_files(files)
    with _compile_lock:
        sources, _expanded, errors = _sources(files)
        if errors:
            raise CompileFailed(errors)
        out: list[tuple[_Source, drl_items.SourceItems | None]] = []
        for source in sources:
            problems, described = _parse(source)
            if problems:
                raise CompileFailed(problems)
            out.append((source, drl_items.parse_items(source.file, source.drl, described) if described else None))
        return out


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


def _sources(files: dict[str, str]) -> tuple[list[_Source], dict[str, str], list[CompileError]]:
    dsl_key = content_hash({f: t for f, t in files.items() if f.endswith(".dsl")})
    if any(f.endswith(".dslr") and (f, files[f], dsl_key) not in _expansions for f in files):
        mappings, errors = _parse_dsl_files(files)
    else:  # every .dslr expanded before with these very mappings
        mappings, errors = {}, []
    sources: list[_Source] = []
    expanded: dict[str, str] = {}
    for fname, text in sorted(files.items()):
        if fname.endswith(".drl"):
            sources.append(_Source(fname, text))
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
                sources.append(_Source(fname, drl, line_map))
        elif is_table_file(fname):
            table = decision_table.convert(fname, text)
            errors.extend(table.errors)
            if table.drl is not None:
                expanded[fname] = table.drl
                if not table.errors:
                    sources.append(_Source(fname, table.drl, table=table))
    return sources, expanded, errors


def _in_tables(errors: list[CompileError], sources: list[_Source]) -> list[CompileError]:
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


def _parse_cached(source: _Source) -> tuple[list[CompileError], str | None]:
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
    from gateway.engine import incremental
    from gateway.engine.errors import InvalidRuleSet

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
            errors.extend(scenarios.format_errors(files))  # a malformed tests/*.yaml is refused like bad rules
            described: list[str | None] = []
            for n, source in enumerate(sources):
                errs, info = _parse_cached(source)
                errors.extend(errs)
                described.append(info)
                if on_progress is not None:
                    incremental._progress(on_progress, n + 1, len(sources), "parse")
            if errors:
                raise CompileFailed(_sorted(_in_tables(errors, sources)))
            try:
                return incremental.build(files, sources, described, expanded, label, options, on_progress)
            except CompileFailed as failed:
                raise CompileFailed(_sorted(_in_tables(failed.errors, sources))) from None
        except _OOM_TYPES() as exc:  # anywhere on the way: the author's text is not to blame
            raise incremental.memory_error() from exc


def _OOM_TYPES() -> tuple[type, ...]:
    import jpype

    try:
        return (jpype.JClass("java.lang.OutOfMemoryError"), MemoryError)
    except Exception:  # the JVM is not running yet
        return (MemoryError,)


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


@dataclass
class BuiltUnit:
    """A compiled unit: the executable-model classes Drools generated, zipped, and the model class names."""

    model_classes: list[str]
    data: bytes


def build_unit(sources: list[_Source], unit_id: str, deadline: Any = None) -> BuiltUnit:
    """Compiles DRL texts with the executable model into class bytes (nothing is loaded).

    Errors are mapped to the authors' files, lines and columns (CompileFailed); running out of
    memory, also when Drools reports it as a build message, raises CompileResourceError.
    """
    j = _j()
    ks = j["KieServices"].Factory.get()
    kfs = ks.newKieFileSystem()
    release = ks.newReleaseId("org.printeps.units", f"u{unit_id[:24]}", "1.0.0")
    kfs.generateAndWritePomXML(release)
    by_path: dict[str, _Source] = {}
    for source in sources:
        path = _resource_path("units", source)
        by_path[path.removeprefix("src/main/resources/")] = source
        kfs.write(path, source.drl)
    builder = ks.newKieBuilder(kfs)
    try:
        try:
            builder.buildAll(j["ExecModel"])
        except _OOM_TYPES():
            raise
        except Exception as exc:  # e.g. ConsequenceRewriteException: the builder throws instead of reporting
            if says_out_of_memory(str(exc)):
                raise _memory_error() from None
            raise CompileFailed(_unbound_variables(sources) or [_error_from_exception(exc, sources)]) from None
        if deadline is not None:
            deadline.check()
        messages = list(builder.getResults().getMessages(_error_level()))
        try:
            module = builder.getKieModule()
        except j["CompilationErrors"] as exc:
            messages = list(exc.getErrorMessages()) or messages
            module = None
        if messages:
            if any(says_out_of_memory(str(m.getText())) for m in messages):
                raise _memory_error()
            mapped = _map_build_messages(messages, by_path, sources)
            unbound = _unbound_variables(sources) if any(e.message.startswith("then-part:") for e in mapped) else []
            if unbound:  # the likely cause of the Java errors: say it in the author's terms
                mapped = unbound + [e for e in mapped if not e.message.startswith("then-part:")]
            raise CompileFailed(_sorted(mapped))
        units = jvm.helper_class("Units")
        classes = units.classesOf(module)
        names = [str(n) for n in units.modelClassNames(module)]
        data = bytes(memoryview(units.zip(classes)))
        return BuiltUnit(names, data)
    finally:
        _forget_module(ks, release)


def _forget_module(ks: Any, release: Any) -> None:
    """Remove a built module from the repository (they would otherwise pile up there). Right after
    the JVM ran out of memory even this call can fail (JPype's "Fatal error occurred"): then the
    module is left, and the error being raised, the one that says why, is not replaced by this."""
    try:
        ks.getRepository().removeKieModule(release)
    except Exception as exc:
        log.debug("could not remove the built module %s from the repository: %s", release, exc)


def _memory_error() -> CompileResourceError:
    from gateway.engine import incremental

    return incremental.memory_error()


_PACKAGE = re.compile(r"^\s*package\s+([A-Za-z_][\w.]*)\s*;?", re.MULTILINE)


def _resource_path(label: str, source: _Source) -> str:
    """Where a DRL goes in the KieFileSystem: the folder of its package, as Drools expects."""
    name = source.file if source.file.endswith(".drl") else source.file + ".drl"
    package = _PACKAGE.search(source.drl)
    folder = package.group(1).replace(".", "/") if package else re.sub(r"[^A-Za-z0-9_]", "_", label)
    return f"src/main/resources/{folder}/{name}"


_RULE_BLOCK = re.compile(r'^\s*rule\s+("[^"]*"|\S+)(.*?)^\s*end\b', re.MULTILINE | re.DOTALL)


def _unbound_variables(sources: list[_Source]) -> list[CompileError]:
    """Then-parts that use a ``$variable`` their when-part never binds (a common DSL slip: a
    consequence sentence that needs a condition sentence the rule lacks)."""
    errors: list[CompileError] = []
    for source in sources:
        for rule in _RULE_BLOCK.finditer(source.drl):
            body = rule.group(2)
            parts = re.split(r"^\s*then\b", body, maxsplit=1, flags=re.MULTILINE)
            if len(parts) != 2:
                continue
            bound = set(re.findall(r"(\$\w+)\s*:", parts[0]))
            then_start = rule.start(2) + len(parts[0])
            for used in dict.fromkeys(re.findall(r"\$\w+", parts[1])):
                if used not in bound:
                    offset = then_start + parts[1].index(used)
                    line = source.drl.count("\n", 0, offset) + 1
                    col = offset - (source.drl.rfind("\n", 0, offset) + 1) + 1
                    errors.append(CompileError(
                        source.file, source.source_line(line), col,
                        f"then-part of rule {rule.group(1)} uses {used}, which its when-part does not bind"
                        " (is a condition sentence missing?)",
                    ))
    return errors


def _error_from_exception(exc: Exception, sources: list[_Source]) -> CompileError:
    """A Java exception thrown by the build, located via the rule or fragment it names."""
    text = str(getattr(exc, "getMessage", lambda: exc)() or exc)
    cause = exc
    while getattr(cause, "getCause", None) is not None and cause.getCause() is not None:
        cause = cause.getCause()
    detail = str(cause.getMessage() if hasattr(cause, "getMessage") else cause)
    message = detail if detail and detail != "None" else text
    found = _locate_fragment(f"{text} {detail}", sources)
    if found:
        src, line, col = found
        return CompileError(src.file, src.source_line(line), col, message)
    return CompileError(sources[0].file if sources else "", 0, 0, message)


def _kiebase_configuration(ks: Any) -> Any:
    """Stream mode, so rule sets may declare events (@role(event)) with temporal operators."""
    import jpype

    conf = ks.newKieBaseConfiguration()
    conf.setOption(jpype.JClass("org.kie.api.conf.EventProcessingOption").STREAM)
    return conf


def _error_level():
    import jpype

    return jpype.JClass("org.kie.api.builder.Message$Level").ERROR


def _map_build_messages(messages: list[Any], by_path: dict[str, _Source], sources: list[_Source]) -> list[CompileError]:
    errors: list[CompileError] = []
    generated = _generated_sources(messages)
    for msg in messages:
        text = str(msg.getText())
        path = str(msg.getPath()) if msg.getPath() is not None else ""
        line, col = int(msg.getLine()), int(msg.getColumn())
        if text.startswith("Java source of "):
            continue  # the generated source dump that accompanies a Java error
        if path.startswith("src/main/java/"):
            errors.append(_locate_java_error(text, line, generated.get(path, []), sources))
            continue
        source = by_path.get(path)
        if source is None:
            source = next((s for s in sources if path.endswith(s.file) or path.endswith(s.file + ".drl")), None)
        if line <= 0 or source is None:
            found = _locate_fragment(text, sources if source is None else [source])
            if found:
                fsrc, line, col = found
                errors.append(CompileError(fsrc.file, fsrc.source_line(line), col, _clean_build_message(text)))
                continue
        if source is not None:
            line = source.source_line(line)
        errors.append(CompileError(source.file if source else path, max(line, 0), max(col, 0), _clean_build_message(text)))
    return _unique(errors)


def _clean_build_message(text: str) -> str:
    text = text.strip().split("\n")[0]
    text = re.sub(r", expected one of .*$", "", text)
    text = re.sub(r"^\[ERR \d+\]\s*", "", text)
    if text.startswith("Unable to find class: "):
        return f"unknown type '{text.removeprefix('Unable to find class: ').strip()}'"
    if text.startswith("Unable to parse left part of expression: "):
        expr = text.removeprefix("Unable to parse left part of expression: ")
        return f"unknown field or invalid expression: '{expr}'"
    return text


def _locate_fragment(text: str, sources: list[_Source]) -> tuple[_Source, int, int] | None:
    """Finds where an error message's subject (a type name, an expression) stands in the sources."""
    candidates: list[str] = []
    for prefix in ("Unable to find class: ", "Unable to parse left part of expression: ", "Unknown property "):
        if prefix in text:
            candidates.append(text.split(prefix, 1)[1].strip().split("\n")[0])
    candidates += re.findall(r"The method (\w+)\(", text) + re.findall(r"(\S+) cannot be resolved", text)
    candidates += re.findall(r"'([^']{2,})'", text) + re.findall(r'"([^"]{2,})"', text)
    for cand in candidates:
        pattern = re.compile(r"(?<![A-Za-z0-9_])" + re.escape(cand) + r"(?![A-Za-z0-9_])")
        for source in sources:
            found = _search_code(source.drl, pattern)
            if found:
                return source, found[0], found[1]
    rule = re.search(r'rule "?([^"]+)"?', text)
    if rule:
        pattern = re.compile(r'^\s*rule\s+"?' + re.escape(rule.group(1)), re.MULTILINE)
        for source in sources:
            found = _search_code(source.drl, pattern)
            if found:
                return source, found[0], found[1]
    return None


def _search_code(text: str, pattern: re.Pattern[str]) -> tuple[int, int] | None:
    """First match outside comments, as (line, column), 1-based."""
    for lineno, line in enumerate(text.split("\n"), start=1):
        code = re.split(r"//|#", line, maxsplit=1)[0] if not line.lstrip().startswith('"') else line
        m = pattern.search(code)
        if m:
            return lineno, m.start() + 1
    return None


def _locate_java_error(text: str, line: int, generated: list[str], sources: list[_Source]) -> CompileError:
    """A then-part Java error points into generated code: find the offending statement in the sources."""
    statement = ""
    if generated and 0 < line <= len(generated):
        statement = generated[line - 1].strip()
    message = f"then-part: {text.strip()}"
    if statement:
        candidates = [statement, statement.rstrip(";")]
        for cand in candidates:
            pattern = re.compile(re.escape(cand))
            for source in sources:
                found = _search_code(source.drl, pattern)
                if found:
                    return CompileError(source.file, source.source_line(found[0]), found[1], message)
    found = _locate_fragment(text, sources)
    if found:
        return CompileError(found[0].file, found[0].source_line(found[1]), found[2], message)
    return CompileError(sources[0].file if sources else "", 0, 0, message)


def _generated_sources(messages: list[Any]) -> dict[str, list[str]]:
    """Generated Java files by path, from the "Java source of <path> in error:" companion messages."""
    out: dict[str, list[str]] = {}
    for msg in messages:
        text = str(msg.getText())
        m = re.match(r"Java source of (\S+) in error:\n", text)
        if m:
            out[m.group(1)] = text[m.end():].split("\n")
    return out


def _unique(errors: list[CompileError]) -> list[CompileError]:
    seen: set[tuple[str, int, str]] = set()
    out: list[CompileError] = []
    for e in errors:
        key = (e.file, e.line, e.message)
        if key not in seen:
            seen.add(key)
            out.append(e)
    return out


def _sorted(errors: list[CompileError]) -> list[CompileError]:
    return sorted(_unique(errors), key=lambda e: (e.file, e.line, e.column))
