"""One build step of a rule set, and the types a build hands around.

Why a module of its own: the compiler (:mod:`gateway.engine.compiler`: checks, DSL expansion,
parsing, the compile cache) and the incremental build (:mod:`gateway.engine.incremental`: units,
their cache, assembling a KieBase) both need these, and neither should reach into the other.

- :class:`CompiledRuleSet` and :class:`CompileOptions`, what a build gives and how it is done;
- :class:`Source`, a DRL text to compile and the file it came from;
- :func:`build_unit`, the one place a DRL text meets Drools' executable-model builder, with the
  mapping of its failures to the authors' files, lines and columns (:func:`sorted_errors`);
- :func:`kiebase_configuration`, :func:`memory_error` and :func:`resource_error_of`, shared by every build.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass, field
from typing import Any, Callable

from gateway.base import jvm
from gateway.engine import decision_table
from gateway.engine.errors import CompileError, CompileFailed, CompileResourceError, says_out_of_memory

log = logging.getLogger(__name__)


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
    request_joins: str = "auto"  # one-shot fires of all-plain sets read joined facts from the request: auto | always | never

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
            request_joins=pick("request_joins", "auto"),
        )


DEFAULT_OPTIONS = CompileOptions()


Progress = Callable[[int, int, str], None]


@dataclass
class Source:
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


def java_classes() -> dict[str, Any]:
    global _J
    if _J is None:
        _J = _java()
    return _J


def oom_types() -> tuple[type, ...]:
    import jpype

    try:
        return (jpype.JClass("java.lang.OutOfMemoryError"), MemoryError)
    except Exception:  # the JVM is not running yet
        return (MemoryError,)


@dataclass
class BuiltUnit:
    """A compiled unit: the executable-model classes Drools generated, zipped, and the model class names."""

    model_classes: list[str]
    data: bytes


def build_unit(sources: list[Source], unit_id: str, deadline: Any = None) -> BuiltUnit:
    """Compiles DRL texts with the executable model into class bytes (nothing is loaded).

    Errors are mapped to the authors' files, lines and columns (CompileFailed); running out of
    memory, also when Drools reports it as a build message, raises CompileResourceError.
    """
    j = java_classes()
    ks = j["KieServices"].Factory.get()
    kfs = ks.newKieFileSystem()
    release = ks.newReleaseId("org.printeps.units", f"u{unit_id[:24]}", "1.0.0")
    kfs.generateAndWritePomXML(release)
    by_path: dict[str, Source] = {}
    for source in sources:
        path = _resource_path("units", source)
        by_path[path.removeprefix("src/main/resources/")] = source
        kfs.write(path, source.drl)
    builder = ks.newKieBuilder(kfs)
    try:
        try:
            builder.buildAll(j["ExecModel"])
        except oom_types():
            raise
        except Exception as exc:  # e.g. ConsequenceRewriteException: the builder throws instead of reporting
            if says_out_of_memory(str(exc)):
                raise memory_error() from None
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
                raise memory_error()
            mapped = _map_build_messages(messages, by_path, sources)
            unbound = _unbound_variables(sources) if any(e.message.startswith("then-part:") for e in mapped) else []
            if unbound:  # the likely cause of the Java errors: say it in the author's terms
                mapped = unbound + [e for e in mapped if not e.message.startswith("then-part:")]
            raise CompileFailed(sorted_errors(mapped))
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


def memory_error() -> CompileResourceError:
    """The error a build raises when the JVM runs out of memory (it names the heap limit and its setting)."""
    heap = ""
    try:
        runtime = jvm.jclass("java.lang.Runtime").getRuntime()
        heap = f"{int(runtime.maxMemory()) // (1024 * 1024)} MB"
        jvm.jclass("java.lang.System").gc()  # give back what the failed build held
    except Exception:  # the JVM may be in no state to answer
        pass
    return CompileResourceError(
        "memory", "the JVM ran out of memory while compiling" + (f" (heap limit {heap})" if heap else ""),
        setting="PRINTEPS_JVM_HEAP (jvm.max_heap)", limit=heap or None)


_PACKAGE = re.compile(r"^\s*package\s+([A-Za-z_][\w.]*)\s*;?", re.MULTILINE)


def _resource_path(label: str, source: Source) -> str:
    """Where a DRL goes in the KieFileSystem: the folder of its package, as Drools expects."""
    name = source.file if source.file.endswith(".drl") else source.file + ".drl"
    package = _PACKAGE.search(source.drl)
    folder = package.group(1).replace(".", "/") if package else re.sub(r"[^A-Za-z0-9_]", "_", label)
    return f"src/main/resources/{folder}/{name}"


_RULE_BLOCK = re.compile(r'^\s*rule\s+("[^"]*"|\S+)(.*?)^\s*end\b', re.MULTILINE | re.DOTALL)


def _unbound_variables(sources: list[Source]) -> list[CompileError]:
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


def _error_from_exception(exc: Exception, sources: list[Source]) -> CompileError:
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


def kiebase_configuration(ks: Any) -> Any:
    """Stream mode, so rule sets may declare events (@role(event)) with temporal operators."""
    import jpype

    conf = ks.newKieBaseConfiguration()
    conf.setOption(jpype.JClass("org.kie.api.conf.EventProcessingOption").STREAM)
    return conf


def _error_level():
    import jpype

    return jpype.JClass("org.kie.api.builder.Message$Level").ERROR


def _map_build_messages(messages: list[Any], by_path: dict[str, Source], sources: list[Source]) -> list[CompileError]:
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


def _locate_fragment(text: str, sources: list[Source]) -> tuple[Source, int, int] | None:
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


def _locate_java_error(text: str, line: int, generated: list[str], sources: list[Source]) -> CompileError:
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


def sorted_errors(errors: list[CompileError]) -> list[CompileError]:
    return sorted(_unique(errors), key=lambda e: (e.file, e.line, e.column))


def resource_error_of(exc: BaseException) -> CompileResourceError | None:
    """A CompileResourceError if ``exc`` (or its cause chain) is the JVM running out of memory."""
    text = f"{type(exc).__name__}: {exc}"
    cause = getattr(exc, "getCause", None)
    seen = 0
    while cause is not None and seen < 10:
        inner = cause()
        if inner is None:
            break
        text += f" {inner.getClass().getName()}: {inner.getMessage()}"
        cause = getattr(inner, "getCause", None)
        seen += 1
    if says_out_of_memory(text):
        return memory_error()
    return None
