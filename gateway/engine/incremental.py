"""Incremental builds: a rule set compiled in units, each rule reused from earlier builds while it
and what it depends on are unchanged, and one KieBase assembled from all of them.

Why: Drools' executable model compiles a whole rule set every time (~5 ms of CPU a rule: 10 s for
1,000 rules, a minute for 10,000), while building the Rete network from compiled rules takes a
fraction of that. Business Central users expect changing one rule among thousands to feel instant.

How a build goes (:func:`build`):

1. every DRL text is split into items (:mod:`gateway.engine.drl_items`); each rule gets a key over
   everything its compiled classes depend on;
2. the **declarations unit** (every file with its rules blanked out: declared types, globals,
   functions, queries) is taken from the cache or compiled; its classes are the parent of every
   rule unit's class loader, so all rules share one set of declared classes;
3. rules whose key some cached unit holds are taken from it; rules of the plain shapes
   (:mod:`gateway.engine.plain_rules`) are built at run time without code generation (**plain
   units**, cached as their description); the others are compiled in batches (**rule units**: every
   file with all rules but the batch's blanked out, so line and column of an error are those of the
   author's file), on ``workers`` threads, each unit cached (memory + disk);
4. one KieBase is assembled (``Units.assemble``) from the declarations and the rules in the order of
   the text (files by name, rules as written), which is also the order a one-unit build gets, so
   rules of equal salience fire in the same order however the set was split;
5. the assembly plan is kept under the set's content hash: loading the same set again (another
   process, the next start) parses and compiles nothing.

Texts the splitter cannot place unambiguously, and rule units (``unit`` declarations), are built as
one unit (``mode="whole"``), like ``incremental=False``.
"""

from __future__ import annotations

import concurrent.futures
import itertools
import json
import logging
import math
import os
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gateway.base import jvm, priority
from gateway.engine import drl_items, plain_rules, shared_patterns
from gateway.engine.build import (
    CompiledRuleSet,
    CompileOptions,
    Source,
    build_unit,
    java_classes,
    kiebase_configuration,
    resource_error_of,
    sorted_errors,
)
from gateway.engine.drl_items import RuleSetItems, SourceItems
from gateway.engine.errors import BuildCancelled, CompileError, CompileFailed, CompileResourceError
from gateway.engine.ruleset import content_hash
from gateway.engine.unit_cache import UnitArtifact, UnitCache

log = logging.getLogger(__name__)

Progress = Callable[[int, int, str], None]
MAX_BATCH = 250  # rules per rule unit: bounds a unit's compile memory, leaves work for every worker
FORMAT_VERSION = "units-2"  # units-2: plain units (rules built at run time)


@dataclass
class BuildStats:
    """What a build did, for logs, benchmarks and the deploy job's answer."""

    mode: str = "incremental"  # incremental | whole | plan (loaded from a cached plan)
    rules: int = 0
    rules_compiled: int = 0
    rules_built: int = 0  # plain rules built at run time, without code generation
    units_compiled: int = 0
    units_reused: int = 0
    compile_s: float = 0.0
    load_s: float = 0.0
    assemble_s: float = 0.0
    request_joins_s: float = 0.0  # building the request-join network of one-shot fires (0: none built)
    total_s: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass
class _Loaded:
    loader: Any  # Units.UnitClassLoader
    models: Any  # java.util.List<Model>
    rules: int = 0
    token: str = ""  # unique per load: units loaded under it are keyed by it, never by a unit id alone


@dataclass
class _Plan:
    """How to assemble a rule set: its declarations unit and, in order, where each rule comes from."""

    declarations: str
    rules: list[tuple[str, str, str]] = field(default_factory=list)  # (unit id, package, rule name)
    whole: bool = False


# --------------------------------------------------------------------------- process-wide state

_cache: UnitCache | None = None
_cache_config: tuple[Any, ...] | None = None
_shared: Any = None  # the tier shared with other hosts (share_units)
_loaded: OrderedDict[tuple[str, str], _Loaded] = OrderedDict()
_loaded_lock = threading.RLock()
MAX_LOADED_RULES = 60_000  # loaded units kept for the next build (their classes live on in KieBases anyway)


def env_key() -> str:
    """What generated classes are valid for: this Drools, the helper classes generated code calls
    (the ``actions`` global), this unit format and plain rule description format. Other helper
    changes keep the cache (a plain unit is built again from its description by the current code)."""
    units = jvm.helper_class("Units")
    linked = {k: v for k, v in jvm.helper_sources().items() if k.endswith(".Actions")}
    helpers = drl_items.digest(*(f"{k}\0{v}" for k, v in sorted(linked.items())))
    return f"drools-{units.droolsVersion()}-{FORMAT_VERSION}.{plain_rules.FORMAT}-{helpers[:12]}"


def default_cache_dir() -> Path:
    """The per-user cache shared by every gateway process on the host (as the Java helpers')."""
    return Path(os.environ.get("PRINTEPS_CACHE_DIR", Path.home() / ".cache" / "printeps")) / "rule-units"


def unit_cache(options: CompileOptions) -> UnitCache:
    """The process's unit cache for these options (one per cache directory and bounds)."""
    global _cache, _cache_config
    root = None if not options.disk_cache else Path(options.cache_dir) if options.cache_dir else default_cache_dir()
    config = (root, options.memory_cache_mb, options.disk_cache_mb)
    if _cache is None or _cache_config != config:
        _cache = UnitCache(root, env_key(), options.memory_cache_mb, options.disk_cache_mb)
        _cache_config = config
    _cache.shared = _shared
    return _cache


def share_units(shared: Any) -> None:
    """Share compiled units and plans with other hosts through ``shared`` (a
    :class:`gateway.store.unit_store.SharedUnitStore`; None: this host only). The composition
    root sets it when the gateway runs on an Information State."""
    global _shared
    _shared = shared


def reset() -> None:
    """Forget the process's cache objects and loaded units (tests; a changed cache directory)."""
    global _cache, _cache_config
    with _loaded_lock:
        _loaded.clear()
    _cache = None
    _cache_config = None


# --------------------------------------------------------------------------- build


class _Deadline:
    """The compile time limit, checked between units (a unit that runs keeps running, unused)."""

    def __init__(self, timeout_s: float | None):
        self.timeout_s = timeout_s
        self.at = time.monotonic() + timeout_s if timeout_s else None
        self.cancelled = threading.Event()

    def remaining(self) -> float | None:
        return None if self.at is None else self.at - time.monotonic()

    def check(self) -> None:
        if self.cancelled.is_set() or (self.at is not None and time.monotonic() > self.at):
            self.cancelled.set()
            raise _timeout(self.timeout_s)


def _timeout(timeout_s: float | None) -> CompileResourceError:
    return CompileResourceError(
        "time", f"compiling took longer than the compile time limit of {timeout_s:g} s",
        setting="PRINTEPS_COMPILE_TIMEOUT (engine.compile_timeout_s)", limit=f"{timeout_s:g} s")


def build(
    files: dict[str, str],
    sources: list[Source],
    described: list[str | None],
    expanded: dict[str, str],
    label: str,
    options: CompileOptions,
    on_progress: Progress | None = None,
) -> CompiledRuleSet:
    """Compiles ``sources`` (syntax-checked, ``described`` by ``Units.describe``) in units; raises
    CompileFailed with positioned errors, or CompileResourceError when out of memory or time."""

    started = time.perf_counter()
    deadline = _Deadline(options.timeout_s)
    cache = unit_cache(options)
    env = cache.dir.name if cache.dir is not None else env_key()
    stats = BuildStats()
    items = _split(sources, described)
    if items is None or not options.incremental:
        stats.mode = "whole"
        plan = _compile_whole(sources, items, env, cache, deadline, stats, on_progress, options)
    else:
        plan = _compile_incremental(sources, items, env, cache, deadline, stats, on_progress, options)
    compiled = assemble(plan, files, expanded, cache, stats, on_progress, request_joins=options.request_joins)
    stats.total_s = time.perf_counter() - started
    if options.incremental and options.disk_cache:
        cache.put_plan(content_hash(files), _plan_to_json(plan, expanded))
    log.info("built %s: %d rules, %d compiled in %d units, %d units reused, %.2f s (%s)", label, stats.rules,
             stats.rules_compiled, stats.units_compiled, stats.units_reused, stats.total_s, stats.mode)
    return compiled


def _split(sources: list[Source], described: list[str | None]) -> RuleSetItems | None:
    split: list[SourceItems] = []
    for source, info in zip(sources, described):
        if info is None:
            return None
        items = drl_items.parse_items(source.file, source.drl, info)
        if items is None or items.unit or any(i.parent for i in items.items):
            return None  # unplaceable items, rule units, rule inheritance: one unit
        split.append(items)
    return RuleSetItems.of(split)


def _compile_whole(sources, items, env, cache, deadline, stats, on_progress, options) -> _Plan:
    """The whole set as one unit (the non-incremental path, and the fallback). Its rules are not
    offered to other builds: taking one would load all of them."""

    unit_id = drl_items.digest("whole", env, *(f"{s.file}\0{s.drl}" for s in sources))
    order: list[tuple[str, str, str]] = []
    if items is not None:
        _check_duplicates(items, sources)
        for src in sorted(items.sources, key=lambda s: s.file):
            order.extend((unit_id, src.package, item.name) for item in src.rules)
    stats.rules = len(order)
    unit = cache.get(unit_id) if options.incremental else None
    if unit is None:
        _progress(on_progress, 0, max(len(order), 1), "compile")
        started = time.perf_counter()
        built = _run_with_deadline(lambda: build_unit(sources, unit_id, deadline), deadline)
        stats.compile_s = time.perf_counter() - started
        unit = UnitArtifact(unit_id, "whole", built.model_classes, {}, built.data)
        cache.put(unit, persist=options.incremental and options.disk_cache)
        stats.units_compiled, stats.rules_compiled = 1, len(order)
        _progress(on_progress, max(len(order), 1), max(len(order), 1), "compile")
    else:
        stats.units_reused = 1
    return _Plan(unit_id, order, whole=True)


def _compile_incremental(sources, items: RuleSetItems, env, cache: UnitCache, deadline, stats, on_progress,
                         options) -> _Plan:
    _check_duplicates(items, sources)
    by_file = {s.file: s for s in sources}
    apart = plain_rules.queries_apart(items.sources) if options.plain_rules else {}  # (file, start) -> description
    decl_id = items.declarations_key(env, apart)
    order: list[tuple[str, SourceItems, drl_items.Item]] = []
    for src in sorted(items.sources, key=lambda s: s.file):
        for item in src.items:
            if item.kind == "rule" or (src.file, item.start) in apart:
                order.append((items.rule_key(env, src, item), src, item))
    stats.rules = sum(item.kind == "rule" for _, _, item in order)  # the queries built apart aside
    cache.refresh()
    found: dict[str, str] = {}
    missing: list[tuple[str, SourceItems, drl_items.Item]] = []
    available: dict[str, bool] = {}
    for key, src, item in order:
        unit_id = cache.find_rule(key)
        if unit_id is not None:
            if unit_id not in available:
                available[unit_id] = cache.get(unit_id) is not None
            if not available[unit_id]:
                cache.forget_rule(key, unit_id)
                unit_id = None
        if unit_id is None:
            missing.append((key, src, item))
        else:
            found[key] = unit_id
    stats.units_reused = len(set(found.values()))
    plain, missing = _plain_rules(items, missing, apart) if options.plain_rules else ([], missing)
    jobs: list[tuple[str, list[tuple[str, SourceItems, drl_items.Item]]]] = []
    declarations_ready = threading.Event()  # set once the declarations unit is loaded (or failed)
    declarations: list[_Loaded] = []
    cached_declarations = cache.get(decl_id)
    if cached_declarations is None:
        jobs.append(("declarations", []))
    else:
        stats.units_reused += 1
        declarations.append(_load(cached_declarations, None))
        declarations_ready.set()
    batch = _batch_size(len(missing), options.workers)
    for k in range(0, len(missing), batch):
        jobs.append(("rules", missing[k:k + batch]))
    for group in ([p for p in plain if p[2].kind == "rule"], [p for p in plain if p[2].kind == "query"]):
        for k in range(0, len(group), MAX_PLAIN_BATCH):  # last: they wait for the declarations unit
            jobs.append(("plain", group[k:k + MAX_PLAIN_BATCH]))  # queries: units of their own
    total = max(len(missing) + len(plain), 1)
    done = 0
    _progress(on_progress, 0, total, "compile")
    errors: list[CompileError] = []

    def run(kind: str, rules: list[tuple[str, SourceItems, drl_items.Item]]) -> tuple[UnitArtifact | None, list]:
        """Builds one unit; returns it and the rules it left to the compiler (plain units only)."""
        deadline.check()
        if kind == "plain":
            if not declarations_ready.wait(timeout=_wait_timeout(deadline)) or not declarations:
                return None, []  # the declarations did not compile: their errors are reported
            return _build_plain(rules, env, declarations[0])
        if kind == "declarations":
            try:
                unit_sources = [_unit_source(by_file[s.file], s, s.blanked(lambda i, s=s: i.kind != "rule" and (
                    s.file, i.start) not in apart)) for s in items.sources if not s.only(apart)]
                built = build_unit(unit_sources, decl_id, deadline)
                unit = UnitArtifact(decl_id, "declarations", built.model_classes, {}, built.data)
                declarations.append(_load(unit, None))
                return unit, []
            finally:
                declarations_ready.set()
        wanted = {(src.file, item.start) for _, src, item in rules}
        unit_id = drl_items.digest("rules", env, *(key for key, _, _ in rules))
        unit_sources = []
        for s in items.sources:  # its declarations (no query built apart: no rule calls one) and its rules
            text = s.blanked(lambda i, s=s: (s.file, i.start) in wanted
                             or (i.kind != "rule" and (s.file, i.start) not in apart))
            unit_sources.append(_unit_source(by_file[s.file], s, text))
        built = build_unit(unit_sources, unit_id, deadline)
        unit = UnitArtifact(unit_id, "rules", built.model_classes,
                            {key: (src.package, item.name) for key, src, item in rules}, built.data)
        # load it here, while other workers compile: the assembly then only links
        if declarations_ready.wait(timeout=_wait_timeout(deadline)) and declarations:
            _load(unit, declarations[0])
        return unit, []

    compile_started = time.perf_counter()
    if jobs:
        workers = max(1, min(options.workers, len(jobs)))
        pool = priority.background_pool(workers, "rule-compiler")
        try:
            futures = {pool.submit(run, kind, rules): (kind, rules) for kind, rules in jobs}
            pending = set(futures)
            while pending:
                finished, pending = concurrent.futures.wait(
                    pending, timeout=_heartbeat_timeout(deadline), return_when=concurrent.futures.FIRST_COMPLETED)
                if not finished:
                    deadline.check()
                    _progress(on_progress, min(done, total), total, "compile")  # heartbeat: a cancel is heard
                    continue
                for future in finished:
                    kind, rules = futures[future]
                    try:
                        unit, leftovers = future.result()
                    except CompileFailed as failed:
                        errors.extend(failed.errors)
                        leftovers = []
                    else:
                        if unit is not None:
                            cache.put(unit, persist=options.disk_cache)
                            for key in unit.rules:
                                found[key] = unit.id
                            stats.units_compiled += 1
                            if kind == "plain":
                                stats.rules_built += len(unit.rules)
                            else:
                                stats.rules_compiled += len(rules)
                    size = _batch_size(len(leftovers), options.workers)
                    for k in range(0, len(leftovers), size):  # plain rules the Java side refused
                        more = pool.submit(run, "rules", leftovers[k:k + size])
                        futures[more] = ("rules", leftovers[k:k + size])
                        pending.add(more)
                    done += len(rules) - len(leftovers)
                    _progress(on_progress, min(done, total), total, "compile")
        except BaseException:
            deadline.cancelled.set()  # workers start nothing new; a running unit finishes unused
            raise
        finally:
            pool.shutdown(wait=not deadline.cancelled.is_set(), cancel_futures=True)
    stats.compile_s = time.perf_counter() - compile_started
    if errors:
        raise CompileFailed(sorted_errors(errors))
    return _Plan(decl_id, [(found[key], src.package, item.name) for key, src, item in order])


MAX_PLAIN_BATCH = 2_000  # plain rules per plain unit (a one-rule edit builds a unit of one)
Missing = list[tuple[str, SourceItems, drl_items.Item]]  # (rule key, its file, the rule)
Plain = list[tuple[str, SourceItems, drl_items.Item, dict]]  # the same and its plain description


def _plain_rules(items: RuleSetItems, missing: Missing, described: dict) -> tuple[Plain, Missing]:
    """``missing`` split into plain rules (with their descriptions: ``described``'s, else made) and the rest."""
    imports = plain_rules.package_imports(items.sources)
    plain: Plain = []
    rest: Missing = []
    for key, src, item in missing:
        package_imports = imports.get(src.package)
        spec = described.get((src.file, item.start)) or (
            plain_rules.describe(src, item, package_imports) if package_imports is not None else None)
        if spec is None:
            rest.append((key, src, item))
        else:
            plain.append((key, src, item, spec))
    return plain, rest


def _build_plain(rules: Plain, env: str, declarations: _Loaded) -> tuple[UnitArtifact | None, Missing]:
    """A plain unit of ``rules`` built against the declarations; the rules the Java side refused
    (logged with the reason) are returned for the compiler."""
    built = _java_build(plain_rules.spec_json([spec for *_, spec in rules]), declarations)
    refused: set[int] = set()
    for line in built.rejected():
        index, _, reason = str(line).partition("\t")
        refused.add(int(index))
        log.debug("rule %r left to the compiler: %s", rules[int(index)][2].name, reason)
    leftovers = [(key, src, item) for k, (key, src, item, _) in enumerate(rules) if k in refused]
    kept = [rule for k, rule in enumerate(rules) if k not in refused]
    if not kept:
        return None, leftovers
    # the models hold the built rules only; so does the unit's cached description
    unit = UnitArtifact(drl_items.digest("plain", env, *(key for key, *_ in kept)), "plain", [],
                        {key: (src.package, item.name) for key, src, item, _ in kept},
                        plain_rules.spec_json([spec for *_, spec in kept]))
    _remember((unit.id, declarations.token),
              _Loaded(declarations.loader, built.models(), len(kept), f"{unit.id}#{next(_load_serial)}"))
    return unit, leftovers


def _java_build(description: bytes, declarations: _Loaded, request_joins: bool = False) -> Any:
    """``PlainRules.build`` of a plain unit's description against the declarations' classes and
    globals (``request_joins``: as the request-join network of one-shot fires, see RequestFacts.java)."""
    return jvm.helper_class("PlainRules").build(declarations.loader, declarations.models, description.decode(), request_joins)


HEARTBEAT_S = 0.5  # how often a long unit's wait reports progress (and hears a cancel)


def _heartbeat_timeout(deadline: _Deadline) -> float:
    remaining = _wait_timeout(deadline)
    return HEARTBEAT_S if remaining is None else min(remaining, HEARTBEAT_S)


def _wait_timeout(deadline: _Deadline) -> float | None:
    remaining = deadline.remaining()
    return None if remaining is None else max(remaining, 0.0) + 0.01


def _run_with_deadline(work: Callable[[], Any], deadline: _Deadline) -> Any:
    """``work()`` in a worker thread, given up on (left to finish unused) at the deadline."""
    if deadline.at is None:
        return work()
    pool = priority.background_pool(1, "rule-compiler")
    try:
        future = pool.submit(work)
        try:
            return future.result(timeout=max(deadline.remaining() or 0.0, 0.0))
        except concurrent.futures.TimeoutError:
            deadline.cancelled.set()
            raise _timeout(deadline.timeout_s) from None
    finally:
        pool.shutdown(wait=False)


def _batch_size(missing: int, workers: int) -> int:
    """Enough units to keep every worker busy, none so large that one unit's compile dominates."""
    if missing <= 0:
        return 1
    return max(1, min(MAX_BATCH, math.ceil(missing / (max(workers, 1) * 3))))


def _unit_source(original: Source, items: SourceItems, text: str) -> Source:

    return Source(original.file, text, original.line_map)


def _check_duplicates(items: RuleSetItems, sources: list[Source]) -> None:
    """Two rules (or queries) of one name in one package: an error a one-unit build reports too,
    but units compiled apart would not see."""
    by_file = {s.file: s for s in sources}
    seen: dict[tuple[str, str], tuple[str, int]] = {}
    errors: list[CompileError] = []
    for src in sorted(items.sources, key=lambda s: s.file):
        for item in src.items:
            if item.kind not in ("rule", "query"):
                continue
            where = (src.package, item.name)
            line = by_file[src.file].source_line(item.line)
            if where in seen:
                first_file, first_line = seen[where]
                errors.append(CompileError(src.file, line, 1,
                                           f"Duplicate rule name: '{item.name}' in package {src.package or '(default)'}"
                                           f" (first defined at {first_file}:{first_line})"))
            else:
                seen[where] = (src.file, line)
    if errors:
        raise CompileFailed(errors)


def _progress(on_progress: Progress | None, done: int, total: int, stage: str) -> None:
    """Report progress; the callback may stop the build by raising BuildCancelled."""
    if on_progress is not None:
        try:
            on_progress(done, total, stage)
        except BuildCancelled:
            raise
        except Exception:  # a broken progress display must not break the build
            log.debug("progress callback failed", exc_info=True)


# --------------------------------------------------------------------------- load and assemble


_load_serial = itertools.count(1)


def _load(unit: UnitArtifact, parent: _Loaded | None) -> _Loaded:
    """The unit's classes defined in a loader of their own under ``parent`` (cached per parent
    loader: a rule unit loaded under another copy of the declarations would see other classes)."""
    import jpype

    key = (unit.id, parent.token if parent is not None else "")
    with _loaded_lock:
        loaded = _loaded.get(key)
        if loaded is not None:
            _loaded.move_to_end(key)
            return loaded
    if unit.kind == "plain":
        return _load_plain(unit, parent, key)
    units = jvm.helper_class("Units")
    classes = units.unzip(jpype.JArray(jpype.JByte)(unit.data))
    loader = units.loader(parent.loader if parent is not None else None, classes)
    loader.loadAll()
    if unit.kind == "rules":
        loader.release()  # nothing compiles against a rule unit: keep only the defined classes
    models = units.models(loader, jpype.JArray(jpype.JString)(unit.model_classes))
    return _remember(key, _Loaded(loader, models, len(unit.rules), f"{unit.id}#{next(_load_serial)}"))


def _remember(key: tuple[str, str], loaded: _Loaded) -> _Loaded:
    """Keep a loaded unit for the next builds, within MAX_LOADED_RULES."""
    with _loaded_lock:
        _loaded[key] = loaded
        while len(_loaded) > 1 and sum(one.rules for one in _loaded.values()) > MAX_LOADED_RULES:
            _loaded.popitem(last=False)
    return loaded


def _load_plain(unit: UnitArtifact, parent: _Loaded | None, key: tuple[str, str]) -> _Loaded:
    """A plain unit's rules built again from its description, against ``parent``'s classes."""
    if parent is None:
        raise _MissingUnit(unit.id)
    built = _java_build(unit.data, parent)
    if len(built.rejected()):  # not for the classes it was built against: treated as a unit gone
        log.warning("plain unit %s no longer builds: %s", unit.id, list(built.rejected())[:3])
        raise _MissingUnit(unit.id)
    return _remember(key, _Loaded(parent.loader, built.models(), len(unit.rules), f"{unit.id}#{next(_load_serial)}"))


def assemble(plan: _Plan, files: dict[str, str], expanded: dict[str, str], cache: UnitCache | None,
             stats: BuildStats, on_progress: Progress | None = None, *, request_joins: str = "auto"
             ) -> CompiledRuleSet:
    """One KieBase from the plan's units, wrapped as a CompiledRuleSet; for an all-plain set, also
    the network its one-shot fires use if ``request_joins`` (auto: ``Runner.requestJoinsPay``,
    always, never) asks for it (:func:`_request_join_base`)."""
    import json

    import jpype


    def fetch(unit_id: str) -> UnitArtifact:
        unit = cache.get(unit_id) if cache is not None else None
        if unit is None:
            raise _MissingUnit(unit_id)
        return unit

    load_started = time.perf_counter()
    try:
        declarations = _load(fetch(plan.declarations), None)
        unit_ids = list(dict.fromkeys(unit_id for unit_id, _, _ in plan.rules))
        loaded: list[_Loaded] = []
        rule_units: list[UnitArtifact] = []  # fetched once: the request-join network reads them again
        for k, unit_id in enumerate(unit_ids):
            if plan.whole and unit_id == plan.declarations:
                loaded.append(declarations)
            else:
                rule_units.append(fetch(unit_id))
                loaded.append(_load(rule_units[-1], declarations))
            _progress(on_progress, k + 1, len(unit_ids), "load")
    except jpype.JException as exc:
        raise resource_error_of(exc) or RuntimeError(f"loading compiled rule units failed: {exc}") from exc
    stats.load_s = time.perf_counter() - load_started
    position = {unit_id: k for k, unit_id in enumerate(unit_ids)}
    j = java_classes()
    ks = j["KieServices"].Factory.get()
    units = jvm.helper_class("Units")
    ArrayList = jpype.JClass("java.util.ArrayList")
    unit_models = ArrayList()
    for one in loaded:
        unit_models.add(one.models)
    _progress(on_progress, 0, 1, "assemble")
    started = time.perf_counter()
    try:
        positions = jpype.JArray(jpype.JInt)([position[u] for u, _, _ in plan.rules])
        packages = jpype.JArray(jpype.JString)([p for _, p, _ in plan.rules])
        names = jpype.JArray(jpype.JString)([n for _, _, n in plan.rules])
        kbase = (units.build(declarations.models, kiebase_configuration(ks)) if plan.whole and not plan.rules else units.assemble(
            declarations.models, unit_models, positions, packages, names, kiebase_configuration(ks)))
        stats.assemble_s = time.perf_counter() - started
        joins = None
        all_plain = (not plan.whole and all(unit.kind == "plain" for unit in rule_units)
                     and not all(plain_rules.queries_only(unit.data) for unit in rule_units))  # some rules, all plain
        if all_plain and (request_joins == "always" or (request_joins == "auto" and j["Runner"].requestJoinsPay(kbase))):
            joined = time.perf_counter()
            joins = _request_join_base(rule_units, declarations, lambda models: units.assemble(
                declarations.models, models, positions, packages, names, kiebase_configuration(ks)))
            stats.request_joins_s = time.perf_counter() - joined
        runner = j["Runner"](kbase) if joins is None else j["Runner"](kbase, joins)
    except jpype.JException as exc:
        resource = resource_error_of(exc)
        if resource is not None:
            raise resource from None
        raise
    _progress(on_progress, 1, 1, "assemble")
    return CompiledRuleSet(
        hash=content_hash(files),
        runner=runner,
        container=None,
        rule_count=int(runner.ruleCount()),
        types=json.loads(str(runner.describeTypes())),
        type_names=json.loads(str(runner.typeFullNames())),
        expanded=expanded,
        rule_names=sorted(str(name) for name in runner.ruleNames()),  # not its queries
        kbase=kbase,
        plan=_plan_to_json(plan, expanded),
        stats=stats,
        unit_cache=cache,
    )


def _request_join_base(rule_units: list[UnitArtifact], declarations: _Loaded,
                       assemble_models: Callable[[Any], Any]) -> Any | None:
    """The plain units' rules built again as a request-join network (``PlainRules.build`` with
    ``requestJoins``; docs/engine-api.md, "Request joins"), with what it must know of the whole set
    marked (:mod:`gateway.engine.shared_patterns`). None when a rule does not build so."""
    models = jvm.jclass("java.util.ArrayList")()
    shapes = [shared_patterns.unit_shapes(unit.id, unit.data) for unit in rule_units]
    for unit, marks in zip(rule_units, shared_patterns.marks(shapes)):
        key = (f"{unit.id}#request-joins#{json.dumps(marks, sort_keys=True)}", declarations.token)  # with what the build reads
        with _loaded_lock:
            loaded = _loaded.get(key)
        if loaded is None:
            built = _java_build(shared_patterns.with_marks(unit.data, marks) if marks else unit.data, declarations,
                                request_joins=True)
            if len(built.rejected()):
                log.warning("unit %s builds no request-join network: %s", unit.id, list(built.rejected())[:3])
                return None
            loaded = _remember(key, _Loaded(declarations.loader, built.models(), len(unit.rules),
                                            f"{unit.id}#request-joins#{next(_load_serial)}"))
        models.add(loaded.models)
    return assemble_models(models)


class _MissingUnit(LookupError):
    """A unit of a plan is in no cache any more (evicted): the set is compiled again."""


def build_from_plan(files: dict[str, str], options: CompileOptions, on_progress: Progress | None = None
                    ) -> CompiledRuleSet | None:
    """The rule set assembled from its cached plan and units (nothing parsed or compiled), or None
    when there is no plan or one of its units is gone."""

    if not (options.incremental and options.disk_cache):
        return None
    cache = unit_cache(options)
    saved = cache.get_plan(content_hash(files))
    if saved is None:
        return None
    started = time.perf_counter()
    stats = BuildStats(mode="plan")
    plan = _plan_from_json(saved)
    stats.units_reused = len({u for u, _, _ in plan.rules} | {plan.declarations})
    try:
        compiled = assemble(plan, files, dict(saved.get("expanded", {})), cache, stats, on_progress,
                            request_joins=options.request_joins)
    except _MissingUnit:
        return None
    stats.total_s, stats.rules = time.perf_counter() - started, compiled.rule_count  # rules, not queries
    return compiled


def _plan_to_json(plan: _Plan, expanded: dict[str, str]) -> dict[str, Any]:
    return {"declarations": plan.declarations, "whole": plan.whole, "rules": [list(r) for r in plan.rules],
            "expanded": expanded}


def _plan_from_json(data: dict[str, Any]) -> _Plan:
    return _Plan(data["declarations"], [(u, p, n) for u, p, n in data["rules"]], bool(data.get("whole")))
