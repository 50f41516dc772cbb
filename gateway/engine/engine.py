"""The engine facade: deploy, version, roll back and fire rule sets.

Why a facade: REST, KIE, ROS, the stream processor, workflows and the workbench all need the same
few verbs and the same guarantees — a deploy compiles first and swaps in atomically (requests in
flight finish on the version they started with), a failed build changes nothing, every version is
kept. The live map holds ``name -> LiveRuleSet`` entries; replacing one entry is atomic in Python,
so firing needs no lock.

Versions live in a catalog (:mod:`gateway.base.versions`): the Information State when the gateway has
one, shared by every gateway process. A deploy made here is live here at once; a deploy made by
another process reaches this one through :meth:`sync` (called by the change follower), which
compiles the new version off the serving path and then swaps it in. Each live entry remembers the
sequence number of the catalog change that produced it, so a slower swap can never replace a
newer version. Seeding, loading and following are the shared life cycle of
:mod:`gateway.base.lifecycle`; the engine says how a version is compiled, swapped in and dropped.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from gateway.base import jvm, priority
from gateway.base.lifecycle import CatalogLifecycle, NotAnItem
from gateway.config import Settings, load_settings
from gateway.engine import compiler, explain, kmodule, policy, scenarios, warmup
from gateway.engine.build import CompiledRuleSet
from gateway.engine.errors import (
    CompileError,
    CompileFailed,
    EngineError,
    InvalidRuleSet,
    PolicyRefused,
    RuleSetNotFound,
    VersionConflict,
    VersionNotFound,
)
from gateway.engine.recorder import DecisionRecorder
from gateway.engine.results import FireResult, PreparedFire, decode_result, encode_facts
from gateway.engine.ruleset import check_files, check_name, content_hash, read_folder
from gateway.engine.session import StatefulSession
from gateway.engine.sessions import SessionManager, rule_fingerprints, rule_texts
from gateway.base.versions import Catalog, CatalogConflict, Version, VersionInfo, VersionMissing

log = logging.getLogger(__name__)

Listener = Callable[[str, dict[str, Any]], None]
DRAFT = "(draft)"
# Per-deploy memos of an engine, each bounded: a process deploying every minute for months must
# not keep one entry per version it ever served (found by bench/soak.py; see docs/benchmarks.md).
DECLARED_KEPT = 64  # kmodule declarations by compiled hash (recomputed from the version on a miss)
UNCHANGED_KEPT = 256  # unchanged rules by (rule set, old version, new version): a moving session's refraction
KIND = "ruleset"


@dataclass(frozen=True)
class RuleSetVersion:
    """A rule set version with its files."""

    info: VersionInfo
    files: dict[str, str]

    def to_dict(self) -> dict[str, Any]:
        return {**self.info.to_dict(), "files": dict(self.files)}


@dataclass(frozen=True)
class LiveRuleSet:
    """What a rule set serves: the version, its compiled form, and the catalog change behind it."""

    info: VersionInfo
    compiled: CompiledRuleSet
    seq: int


def _keep(memo: OrderedDict[Any, Any], key: Any, value: Any, limit: int) -> None:
    """Remember ``value`` under ``key``, forgetting the oldest entries past ``limit``."""
    memo.pop(key, None)
    memo[key] = value
    while len(memo) > limit:  # another thread may trim at the same time: forgetting is all this does
        try:
            memo.popitem(last=False)
        except KeyError:
            return


class Engine(CatalogLifecycle):
    """Rule sets by name, each with a live version; thread-safe."""

    kind = KIND
    failures = (EngineError, OSError, UnicodeDecodeError)
    seed_races = (VersionConflict,)

    def __init__(self, settings: Settings | None = None, catalog: Catalog | None = None):
        super().__init__(catalog)
        self.settings = settings or load_settings()
        jvm.configure(self.settings.jvm)
        priority.configure(self.settings.engine.background_nice)
        self._live: dict[str, LiveRuleSet] = {}
        self._listeners: list[Listener] = []
        self._fire_listeners: list[Listener] = []  # those of _listeners that hear decisions ("fire")
        self._declared: OrderedDict[str, kmodule.Declarations] = OrderedDict()  # compiled hash -> its sessions
        self._recent = warmup.RecentRequests()  # each rule set's last requests' facts (warm-up samples)
        self._unchanged: OrderedDict[tuple[str, int, int], list[str]] = OrderedDict()
        self.rule_policy = policy.RulePolicy(tuple(self.settings.engine.rule_policy.allow))
        self._policy_verdicts: dict[str, bool] = {}  # content hash -> passes the rule policy
        self._explainers = explain.ExplainCache()
        self._warm_up = warmup.ProcessWarmUp(self)
        self.session_manager = SessionManager(self, self.settings.sessions)
        self.fire_timeout_ms = int(self.settings.engine.fire_timeout_s * 1000)  # as the Java fire takes it (0: none)
        # sessions follow deploys (their policy); decisions are nothing to them
        self.add_listener(self.session_manager.on_engine_event, fires=False)
        store = self.settings.store  # every decision, from every origin, is recorded by this one recorder
        self.recorder = DecisionRecorder(self._notify, enabled=store.record_fires, max_facts=store.decision_facts_max,
                                         heard=lambda: bool(self._fire_listeners))

    # ------------------------------------------------------------------ events

    def add_listener(self, listener: Listener, *, fires: bool = True) -> None:
        """``listener(kind, payload)`` for "deploy", "rollback", "delete", "sync", and, unless ``fires``
        is False, "fire" (its payload the recorded decision's document, see gateway.engine.recorder);
        errors are logged. Why ``fires``: a decision nobody journals or hears is not built at all."""
        self._listeners.append(listener)
        if fires:
            self._fire_listeners.append(listener)

    def _notify(self, kind: str, payload: dict[str, Any]) -> None:
        for listener in list(self._fire_listeners if kind == "fire" else self._listeners):
            try:
                listener(kind, payload)
            except Exception:  # a broken listener must not break firing
                log.exception("engine listener failed on %s", kind)

    # ------------------------------------------------------------------ compile

    def _compile(self, files: dict[str, str], label: str, on_progress: Callable[[int, int, str], None] | None = None,
                 warm: bool = True) -> CompiledRuleSet:
        """Incremental build (see gateway.engine.incremental), warmed before anyone fires it; the
        sessions a kmodule.xml declares are checked with the rules."""
        problems = kmodule.check(files)
        options = compiler.CompileOptions.from_settings(self.settings.engine)
        try:
            compiled = compiler.compile_cached(files, label, options, on_progress)
        except CompileFailed as failed:
            raise CompileFailed(failed.errors + problems) if problems else failed from None
        if problems:
            raise CompileFailed(problems)
        _keep(self._declared, compiled.hash, kmodule.declarations(files), DECLARED_KEPT)
        if warm:
            warmup.warm(compiled, files, budget_s=self._warm_budget(compiled), recent=self.recent_requests(label))
        return compiled

    def _warm_budget(self, compiled: CompiledRuleSet) -> float:
        """``warm_budget_s``, or for a build that took long a share of its time (at most
        ``warm_max_s``): see gateway.engine.warmup."""
        settings = self.settings.engine
        built_s = compiled.stats.total_s if compiled.stats is not None else 0.0
        return min(settings.warm_max_s, max(settings.warm_budget_s, settings.warm_build_share * built_s))

    RECENT_REQUESTS = warmup.RecentRequests.KEPT  # per rule set: the warm-up samples a new version gets

    def recent_requests(self, name: str) -> list[str]:
        """The facts (JSON) of the last stateless fires of ``name`` in this process, oldest first."""
        return self._recent.of(name)

    def validate(self, name: str, files: dict[str, str],
                 on_progress: Callable[[int, int, str], None] | None = None, *,
                 role: str | None = None) -> list[CompileError]:
        """All compile errors of ``files`` ([] when they compile). Deploys nothing.

        ``on_progress(done, total, stage)`` follows the build (see compiler.compile_files). For a
        ``role`` the rule policy checks (an author), its violations are the errors and nothing is
        compiled."""
        check_name(name)
        refused = self.policy_errors(files, role)
        if refused:
            return refused
        try:
            self._compile(files, name, on_progress, warm=False)
        except CompileFailed as failed:
            return failed.errors
        return []

    # ------------------------------------------------------------------ the rule policy

    def policy_errors(self, files: dict[str, str], role: str | None) -> list[CompileError]:
        """What the rule policy refuses in ``files`` for ``role`` ([] for a developer or for the
        gateway itself, ``role=None``). Runs before anything compiles: see gateway.engine.policy."""
        if not policy.applies_to(role):
            return []
        errors = compiler.policy_errors(files, self.rule_policy)
        self._remember_verdict(content_hash(files), not errors)  # GET /api/rulesets need not check it again
        return errors

    def _remember_verdict(self, digest: str, passes: bool) -> None:
        if len(self._policy_verdicts) >= 4096:  # drafts validated as an author types: keep it bounded
            self._policy_verdicts.clear()
        self._policy_verdicts[digest] = passes

    def check_policy(self, name: str, files: dict[str, str], role: str | None, *, author: str = "",
                     audit: bool = False) -> None:
        """Raises :class:`PolicyRefused` when the policy refuses ``files`` for ``role``; with
        ``audit`` the refusal goes into the catalog's change log (``event: "refused"``)."""
        errors = self.policy_errors(files, role)
        if not errors:
            return
        if audit:
            first = errors[0]
            more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
            try:
                self.catalog.refuse(KIND, name, author=author, role=role or "", comment=f"{first}{more}"[:2000])
            except Exception:  # the refusal stands even when the log cannot be written
                log.exception("rule set %s: could not log the policy refusal", name)
        log.warning("rule set %s: refused by the rule policy for %s (%s): %s", name, author or "?", role, errors[0])
        raise PolicyRefused(errors)

    def policy_of(self, info: VersionInfo) -> str:
        """The least role that may deploy the version ``info`` as it stands: "author" when it passes
        the rule policy, else "developer" (``GET /api/rulesets`` shows it). Cached by content."""
        verdict = self._policy_verdicts.get(info.hash)
        if verdict is None:
            files = self.version(info.name, info.version).files
            verdict = not compiler.policy_errors(files, self.rule_policy)
            self._remember_verdict(info.hash, verdict)
        return "author" if verdict else "developer"

    def expand(self, name: str, files: dict[str, str]) -> dict[str, str]:
        """The DRL each ``.dslr`` file expands to."""
        check_name(name)
        return compiler.expand(files)

    # ------------------------------------------------------------------ versions

    def _live_entry(self, name: str) -> tuple[VersionInfo, CompiledRuleSet]:
        entry = self._live.get(name)
        if entry is None:
            entry = self._load_live(name)
        return entry.info, entry.compiled

    def _load_live(self, name: str) -> LiveRuleSet:
        """The serving entry of ``name``, compiled now if it was never loaded in this process."""
        with self._lock:
            entry = self._live.get(name)
            if entry is not None:
                return entry
            head = self.catalog.head(KIND, name)
            if head is None or not head.live:
                raise RuleSetNotFound(name)
            stored = self.catalog.load(KIND, name, head.current)  # type: ignore[arg-type]
            entry = LiveRuleSet(stored.info, self._compile(stored.payload, name), head.seq)
            self._live[name] = entry
        self.prepare_explain(name, stored.payload, entry.compiled.rule_count)
        return entry

    def _swap(self, name: str, entry: LiveRuleSet | None, seq: int) -> bool:
        """Make ``entry`` live (None: stop serving) unless a newer change is live already."""
        with self._lock:
            old = self._live.get(name)
            if old is not None and old.seq > seq:
                return False
            if entry is None:
                self._live.pop(name, None)
                self.session_manager.dispose_ruleset(name)  # deleted: its sessions go (its history stays)
            else:
                self._live[name] = entry
            return True

    def live_versions(self) -> list[VersionInfo]:
        """What this process serves now, by name (no catalog read: health checks, metrics)."""
        return [entry.info for _, entry in sorted(self._live.items())]

    def list_rulesets(self) -> list[VersionInfo]:
        """The current version of every live rule set."""
        out = []
        for head in self.catalog.heads(KIND):
            if head.live:
                entry = self._live.get(head.name)
                if entry is not None and entry.info.version == head.current:
                    out.append(entry.info)
                else:
                    out.append(self.catalog.load(KIND, head.name, head.current).info)  # type: ignore[arg-type]
        return out

    def current(self, name: str) -> RuleSetVersion:
        check_name(name)
        head = self.catalog.head(KIND, name)
        if head is None or not head.live:
            raise RuleSetNotFound(name)
        return self.version(name, head.current)  # type: ignore[arg-type]

    def versions(self, name: str) -> list[VersionInfo]:
        check_name(name)
        infos = self.catalog.versions(KIND, name)
        if not infos:
            raise RuleSetNotFound(name)
        return infos

    def version(self, name: str, version: int) -> RuleSetVersion:
        check_name(name)
        try:
            stored = self.catalog.load(KIND, name, int(version))
        except VersionMissing:
            if not self.catalog.versions(KIND, name):
                raise RuleSetNotFound(name) from None
            raise VersionNotFound(name, int(version)) from None
        return RuleSetVersion(stored.info, dict(stored.payload))

    def history(self, name: str) -> list[dict[str, Any]]:
        """Deploys, rollbacks and deletes of ``name``, and the changes the rule policy refused
        (``event: "refused"``), oldest first; each with who, in which role, from which process."""
        check_name(name)
        return [{"at": c.at, "ts": c.ts, "event": c.event, "version": c.version, "author": c.author,
                 "role": c.role, "comment": c.comment, "seq": c.seq, "origin": c.origin}
                for c in self.catalog.history(KIND, name)]

    def deploy(
        self,
        name: str,
        files: dict[str, str],
        author: str = "anonymous",
        comment: str = "",
        base_version: int | None = None,
        force: bool = False,
        on_progress: Callable[[int, int, str], None] | None = None,
        *,
        role: str | None = None,
    ) -> VersionInfo:
        """Compiles ``files`` and, only if that succeeds, makes them the live version of ``name``.

        ``base_version`` is the version the author's edit started from: if anyone (in any gateway
        process) deployed in between, :class:`VersionConflict` is raised and nothing changes.
        The rule set's own test scenarios (``tests/*.yaml``) must pass: a red one raises
        :class:`ScenariosFailed` unless ``force``. Compiling happens before anything is stored:
        requests keep hitting the old version until the new one is ready. ``on_progress(done,
        total, stage)`` follows the build (a deploy job reports it). ``role``: the deploying
        principal's; an author's files must pass the rule policy first (:class:`PolicyRefused`,
        logged in the history as ``refused``); None: the gateway itself (seeds, local imports).
        """
        check_name(name)
        started = time.perf_counter()
        self.check_policy(name, files, role, author=author, audit=True)
        compiled = self._compile(files, name, on_progress)
        progress = on_progress or _no_progress
        if not force:
            progress(0, 1, "scenarios")  # a deploy job shows this step too (it can take a moment)
            scenarios.require_green(self, name, files)
            progress(1, 1, "scenarios")
        try:
            info, seq = self.catalog.save(KIND, name, dict(files), author=author, comment=comment,
                                          hash=compiled.hash, base_version=base_version, role=_audit_role(role))
        except CatalogConflict as conflict:
            raise VersionConflict(name, conflict.base, conflict.current) from None
        self._swap(name, LiveRuleSet(info, compiled, seq), seq)
        self.prepare_explain(name, files, compiled.rule_count)
        elapsed = (time.perf_counter() - started) * 1000
        log.info("deployed %s version %d (%d rules) in %.0f ms", name, info.version, compiled.rule_count, elapsed)
        self._notify("deploy", {**info.to_dict(), "rules": compiled.rule_count, "duration_ms": elapsed})
        return info

    def rollback(self, name: str, version: int, author: str = "anonymous", comment: str = "", *,
                 role: str | None = None) -> VersionInfo:
        """Makes an earlier (or any stored) version live again; history keeps the rollback. An
        author may not bring back a version the rule policy refuses (one a developer deployed)."""
        stored = self.version(name, int(version))
        self.check_policy(name, stored.files, role, author=author, audit=True)
        compiled = self._compile(stored.files, name)
        info, seq = self.catalog.set_current(KIND, name, stored.info.version, author=author, comment=comment,
                                             role=_audit_role(role))
        self._swap(name, LiveRuleSet(info, compiled, seq), seq)
        self.prepare_explain(name, stored.files, compiled.rule_count)
        self._notify("rollback", {**info.to_dict(), "by": author})
        return info

    def delete(self, name: str, author: str = "anonymous", *, role: str | None = None) -> None:
        """Stops serving ``name``. Its versions stay stored; a new deploy continues the numbering."""
        check_name(name)
        try:
            seq = self.catalog.delete(KIND, name, author=author, role=_audit_role(role))
        except VersionMissing:
            raise RuleSetNotFound(name) from None
        self._swap(name, None, seq)
        self._notify("delete", {"name": name, "by": author})

    # ------------------------------------------------------------------ the shared life cycle's hooks

    def served(self, name: str) -> tuple[int, int] | None:
        entry = self._live.get(name)
        return (entry.info.version, entry.seq) if entry is not None else None

    def served_names(self) -> list[str]:
        return list(self._live)

    def _apply(self, name: str, stored: Version, seq: int, *, elsewhere: bool) -> None:
        """Compile the version off the serving path (the old one keeps serving meanwhile), then swap."""
        compiled = self._compile(stored.payload, name)
        if self._swap(name, LiveRuleSet(stored.info, compiled, seq), seq):
            self.prepare_explain(name, stored.payload, compiled.rule_count)
            if elsewhere:
                log.info("rule set %s: now serving version %d (changed elsewhere)", name, stored.info.version)
                self._notify("sync", {**stored.info.to_dict()})

    def _withdraw(self, name: str, seq: int) -> None:
        if name in self._live and self._swap(name, None, seq):
            log.info("rule set %s: deleted elsewhere; no longer served", name)
            self._notify("delete", {"name": name, "by": "(another process)"})

    def declared_types(self, name: str) -> dict[str, dict[str, str]]:
        return self._live_entry(name)[1].types

    def type_names(self, name: str) -> dict[str, str]:
        """Simple type name -> fully qualified name (e.g. for KIE Server clients)."""
        return self._live_entry(name)[1].type_names

    def rule_count(self, name: str) -> int:
        return self._live_entry(name)[1].rule_count

    # ------------------------------------------------------------------ firing

    def fire(
        self,
        name: str,
        facts: list[dict[str, Any]],
        fire_limit: int | None = None,
        return_facts: bool = True,
        record_facts: bool = True,
        context: dict[str, Any] | None = None,
        *,
        origin: str = "api",
        correlation_id: str | None = None,
        record: bool = True,
    ) -> FireResult:
        """Fires the live version of ``name`` on ``facts`` in a fresh session (stateless).

        Every fire is a decision: :attr:`recorder` gives it a ``decision_id`` and records it with
        its ``origin`` (rest, kie, stream, ros, workflow…), the caller's ``correlation_id`` and any
        ``context``. ``record=False`` is for trials (a workflow's "try my edits") and for callers
        that record it themselves through :attr:`recorder` (the REST fire route, off the fire thread).
        """
        info, compiled = self._live_entry(name)
        result = self._fire(compiled, name, info.version, facts, fire_limit, return_facts, record_facts)
        if record:
            self.recorder.record(result, facts, origin=origin, correlation_id=correlation_id, context=context)
        return result

    def fire_files(self, files: dict[str, str], facts: list[dict[str, Any]], fire_limit: int | None = None, *,
                   role: str | None = None) -> FireResult:
        """Fires undeployed text (the workbench's "try it"): compile errors raise CompileFailed, an
        author's text the rule policy refuses raises PolicyRefused before anything compiles.
        Not a decision: nothing is recorded."""
        self.check_policy(DRAFT, files, role)
        compiled = self.compile_draft(files)
        return self._fire(compiled, DRAFT, 0, facts, fire_limit, True, True)

    def compile_draft(self, files: dict[str, str], on_progress: Callable[[int, int, str], None] | None = None
                      ) -> CompiledRuleSet:
        """Undeployed text compiled for a dry run ("try it", replay, explain): one path, so whatever
        checks a draft must pass apply to all of them. Compile errors raise CompileFailed."""
        return self._compile(files, "draft", on_progress)

    # ------------------------------------------------------------------ explain (dry runs)

    def explain(self, name: str, facts: list[dict[str, Any]], *, files: dict[str, str] | None = None,
                version: int | None = None, role: str | None = None) -> dict[str, Any]:
        """Why each rule of ``name`` fired on ``facts`` or what stopped it (see gateway.engine.explain):
        the draft ``files`` (checked by the rule policy for ``role`` first, as "try it" is), else
        stored ``version``, else the live version. Not a decision."""
        check_name(name)
        if files is not None:
            label: dict[str, Any] = {"hash": content_hash(files)}
            check_files(files)
            self.check_policy(name, files, role)
        else:
            stored = self.version(name, version) if version is not None else self.current(name)
            files, label = stored.files, {"version": stored.info.version}
        encode_facts(facts, self.settings.engine.max_facts)  # bad facts: the fire's own error, before any build
        return {"ruleset": name, **label, **self._explainers.run(self, files, facts)}

    def prepare_explain(self, name: str, files: dict[str, str], rules: int) -> None:
        """A version of ``name`` went live here: build its explain queries in the background
        (``engine.explain_prebuild``), so its first explanation answers in milliseconds. Only
        for versions of at most ``engine.explain_prebuild_max_rules`` rules: the queries' compile
        grows with the rules and holds the compiler, which a big rule set's next deploy needs."""
        engine_settings = self.settings.engine
        if not engine_settings.explain_prebuild:
            return
        limit = engine_settings.explain_prebuild_max_rules
        if limit and rules > limit:
            log.info("explain queries of %s are built at its first explanation (more than %d rules)", name, limit)
            return
        self._explainers.prebuild(self, name, files)

    def explain_ready(self, files: dict[str, str]) -> bool:
        """Whether explaining ``files`` would find its queries built (no compile)."""
        return self._explainers.has(files)

    def explain_builds(self) -> int:
        """How many explainers this engine built (a counter, for tests and metrics)."""
        return self._explainers.builds

    def explain_timings(self) -> list[tuple[float, float]]:
        """(wall ms, CPU ms of the explain thread) of the last explanations (a bench reads them)."""
        return list(self._explainers.timings)

    def close_explain(self) -> None:
        """Stop explaining (at shutdown): the explain thread ends, detached from the JVM."""
        self._explainers.close()

    def explain_session(self, compiled: CompiledRuleSet) -> explain.ThrowawaySession:
        """A throwaway session of ``compiled`` (not registered, never recorded) for explain."""
        java = self.new_java_session(compiled, "pseudo", "explain", True)
        return explain.ThrowawaySession(java, self.settings.engine.fire_limit, self.settings.engine.max_facts)

    # ------------------------------------------------------------------ replay (dry runs)

    def replay_candidate(self, name: str, *, files: dict[str, str] | None = None, version: int | None = None,
                         on_progress: Callable[[int, int, str], None] | None = None, role: str | None = None
                         ) -> tuple[dict[str, Any], CompiledRuleSet]:
        """The candidate of a replay of ``name`` and how it is named in the answer: a draft
        (``{"hash"}``; checked by the rule policy for ``role`` before it compiles, as "try it" is) or
        a stored version (``{"version"}``; VersionNotFound if there is none)."""
        check_name(name)
        if (files is None) == (version is None):
            raise InvalidRuleSet("a replay candidate is either 'files' (a draft) or 'version', not both or neither")
        if files is not None:
            self.check_policy(name, check_files(files), role)
            return {"hash": content_hash(files)}, self.compile_draft(check_files(files), on_progress)
        stored = self.version(name, int(version))  # type: ignore[arg-type]
        return {"version": stored.info.version}, self._compile(stored.files, name, on_progress, warm=False)

    def replay_fire(self, compiled: CompiledRuleSet) -> Callable[[list[dict[str, Any]]], tuple[list[str], list[Any]]]:
        """``fire(facts) -> (rules fired, actions)`` on ``compiled`` in a fresh session: its
        ``actions`` global only records (nothing reaches a robot) and no decision is recorded."""
        def fire(facts: list[dict[str, Any]]) -> tuple[list[str], list[Any]]:
            result = self._fire(compiled, DRAFT, 0, facts, None, False, False)
            return [f["rule"] for f in result.fired], result.actions
        return fire

    def prepare_fire(self, name: str, facts: list[dict[str, Any]]) -> PreparedFire:
        """A stateless fire of the live version of ``name`` ready to run elsewhere (bad facts refused
        here): the REST route runs it on the rule set's JVM lane (gateway.engine.bulkhead) and reads
        the answer with ``results.finished``. :meth:`fire` does all of it on its caller's thread."""
        info, compiled = self._live_entry(name)
        return PreparedFire(name, info.version, compiled.runner, self._encoded(name, facts),
                            int(self.settings.engine.fire_limit), True, True)

    def _encoded(self, name: str, facts: list[dict[str, Any]]) -> str:
        """``facts`` as the Runner takes them (bad facts raise FactError), kept as a warm-up sample."""
        facts_json = encode_facts(facts, self.settings.engine.max_facts)
        if name != DRAFT:
            self._recent.remember(name, facts_json)
        return facts_json

    def _fire(
        self,
        compiled: CompiledRuleSet,
        name: str,
        version: int,
        facts: list[dict[str, Any]],
        fire_limit: int | None,
        return_facts: bool,
        record_facts: bool,
    ) -> FireResult:
        facts_json = self._encoded(name, facts)
        limit = int(fire_limit or self.settings.engine.fire_limit)
        started = time.perf_counter()
        answer = str(compiled.runner.fire(facts_json, limit, return_facts, record_facts, self.fire_timeout_ms))
        return decode_result(answer, name, version, (time.perf_counter() - started) * 1000)

    # ------------------------------------------------------------------ sessions

    def open_session(self, name: str, record_facts: bool = True, *, clock: str = "pseudo",
                     on_deploy: str | None = None) -> StatefulSession:
        """A long-lived stateful session on the live version of ``name`` (a stream binding's):
        it follows deploys as ``sessions.on_deploy`` says unless ``on_deploy`` is given."""
        return self.session_manager.open(name, kind="stream", clock=clock, on_deploy=on_deploy, record_facts=record_facts)

    def new_session(self, name: str, session_id: str, *, clock: str, on_deploy: str, kind: str, record_facts: bool,
                    on_close: Any) -> StatefulSession:
        """A :class:`StatefulSession` on the live version (the session manager registers it)."""
        info, compiled = self._live_entry(name)
        java = self.new_java_session(compiled, clock, kind, record_facts)
        return StatefulSession(java, name, info.version, self.settings.engine.fire_limit, self.settings.engine.max_facts,
                               on_close=on_close, session_id=session_id, clock=clock, on_deploy=on_deploy, kind=kind,
                               record_facts=record_facts)

    def wrap_session(self, java: Any, name: str, version: int, session_id: str, *, clock: str, on_deploy: str, kind: str,
                     record_facts: bool, on_close: Any) -> StatefulSession:
        """A :class:`StatefulSession` around a Java session built elsewhere (a durable session's rebuild)."""
        return StatefulSession(java, name, version, self.settings.engine.fire_limit, self.settings.engine.max_facts,
                               on_close=on_close, session_id=session_id, clock=clock, on_deploy=on_deploy, kind=kind,
                               record_facts=record_facts)

    def compiled_version(self, name: str, version: int) -> CompiledRuleSet:
        """Version ``version`` of ``name`` compiled (the live one as it is; another from the catalog,
        through the unit cache): a durable session is rebuilt on the version its log names."""
        info, compiled = self._live_entry(name)
        if info.version == int(version):
            return compiled
        return self._compile(self.version(name, int(version)).files, name)

    def new_java_session(self, compiled: CompiledRuleSet, clock: str, kind: str, record_facts: bool) -> Any:
        """A Java ``Session`` of ``compiled``: conversations keep a fact handle registry; each fire
        of it is halted after ``engine.fire_timeout_s``."""
        java = jvm.helper_class("Session")(compiled.runner, record_facts, clock == "realtime", kind != "stream")
        java.setFireTimeoutMs(self.fire_timeout_ms)
        return java

    def live_compiled(self, name: str) -> tuple[VersionInfo, CompiledRuleSet]:
        """What ``name`` serves here now (sessions move to it)."""
        return self._live_entry(name)

    def declared_sessions(self, name: str) -> kmodule.Declarations:
        """The sessions the live version of ``name`` declares (its kmodule.xml, else KIE's defaults)."""
        info, compiled = self._live_entry(name)
        found = self._declared.get(compiled.hash)
        if found is None:
            found = kmodule.declarations(self.version(name, info.version).files)
            _keep(self._declared, compiled.hash, found, DECLARED_KEPT)
        return found

    def unchanged_rules(self, name: str, old: int, new: int) -> list[str]:
        """Rules whose text is the same in versions ``old`` and ``new`` (a moving session's
        matches of these do not fire again; see Refraction.java)."""
        key = (name, old, new)
        found = self._unchanged.get(key)
        if found is None:
            before = rule_fingerprints(rule_texts(self.version(name, old).files))
            after = rule_fingerprints(rule_texts(self.version(name, new).files))
            found = sorted(r for r, digest in after.items() if before.get(r) == digest)
            _keep(self._unchanged, key, found, UNCHANGED_KEPT)
        return found

    def sessions(self) -> list[StatefulSession]:
        return self.session_manager.list()

    def close_session(self, session_id: str) -> None:
        session = self.session_manager.by_id(session_id)
        if session is not None:
            session.close()

    # ------------------------------------------------------------------ warm-up

    def warm_up(self, rounds: int = 2, fires: int = 200, background: bool = True) -> threading.Thread | None:
        """Warm the JIT for a fresh process (see :class:`gateway.engine.warmup.ProcessWarmUp`), in
        a daemon thread by default."""
        return self._warm_up.start(rounds, fires, background)

    def stop_warm_up(self, timeout_s: float = 10.0) -> None:
        """Ends a background warm-up and waits for it (shutting down never races it)."""
        self._warm_up.stop(timeout_s)

    # ------------------------------------------------------------------ the seed folder

    def _seed_paths(self, folder: Path) -> list[Path]:
        """Each ``<folder>/<name>/`` holds one rule set."""
        return sorted(p for p in folder.iterdir() if p.is_dir())

    def _read_seed(self, path: Path) -> tuple[str, dict[str, str]]:
        check_name(path.name)
        files = read_folder(path)
        if not files:
            raise NotAnItem("no rule files")
        return path.name, files

    def _store_seed(self, name: str, item: dict[str, str], path: Path) -> int:
        """A seed is what the repository holds: served as is (its red scenarios show in the Tests view)."""
        try:
            return self.deploy(name, item, author="seed", comment=f"seeded from {path.name}", base_version=0,
                               force=True).version
        except CompileFailed as failed:
            for err in failed.errors or [failed]:
                log.error("%s/%s", path, err)
            raise

    def import_folder(self, folder: Path, author: str, comment: str, *, role: str | None = None) -> str:
        """Deploy ``folder`` as rule set ``folder.name`` when its files differ from the current
        version (``printeps import``). Returns "deployed vN" or "unchanged vN"."""
        name = check_name(folder.name)
        files = check_files(read_folder(folder))
        head = self.catalog.head(KIND, name)
        if head is not None and head.live and self.current(name).info.hash == content_hash(files):
            return f"unchanged v{head.current}"
        info = self.deploy(name, files, author=author, comment=comment, role=role)
        return f"deployed v{info.version}"


def _audit_role(role: str | None) -> str:
    """The role a change is logged with: the principal's, or "local" for the gateway itself and
    local commands (seeds, ``printeps import``), which act with the machine's own rights."""
    return role or "local"


def _no_progress(done: int, total: int, stage: str) -> None:
    """Progress nobody follows."""
