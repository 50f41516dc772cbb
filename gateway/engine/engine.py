"""The engine facade: deploy, version, roll back and fire rule sets.

Why a facade: REST, ROS, the stream processor and the workbench all need the same few verbs and
the same guarantees — a deploy compiles first and swaps in atomically (requests in flight finish on
the version they started with), a failed build changes nothing, every version is kept. The live
map holds ``name -> (VersionInfo, CompiledRuleSet)`` tuples; replacing one entry is atomic in
Python, so firing needs no lock.
"""

from __future__ import annotations

import json
import logging
import threading
import time
from pathlib import Path
from typing import Any, Callable

from gateway import jvm
from gateway.config import Settings, load_settings
from gateway.engine import compiler, warmup
from gateway.engine.compiler import CompiledRuleSet
from gateway.engine.errors import (
    CompileError,
    CompileFailed,
    EngineError,
    InvalidRuleSet,
    RuleSetNotFound,
    VersionConflict,
)
from gateway.engine.registry import RuleSetVersion, VersionInfo, VersionStore
from gateway.engine.results import FireResult, decode_result, encode_facts
from gateway.engine.ruleset import check_name, content_hash, read_folder
from gateway.engine.session import StatefulSession

log = logging.getLogger(__name__)

Listener = Callable[[str, dict[str, Any]], None]
DRAFT = "(draft)"


class Engine:
    """Rule sets by name, each with a live version; thread-safe."""

    def __init__(self, settings: Settings | None = None):
        self.settings = settings or load_settings()
        jvm.configure(self.settings.jvm)
        self.store = VersionStore(Path(self.settings.data_dir) / "registry")
        self._live: dict[str, tuple[VersionInfo, CompiledRuleSet]] = {}
        self._lock = threading.RLock()
        self._listeners: list[Listener] = []
        self._sessions: dict[str, StatefulSession] = {}

    # ------------------------------------------------------------------ events

    def add_listener(self, listener: Listener) -> None:
        """``listener(kind, payload)`` for "deploy", "rollback", "delete", "fire" (errors are logged)."""
        self._listeners.append(listener)

    def _notify(self, kind: str, payload: dict[str, Any]) -> None:
        for listener in list(self._listeners):
            try:
                listener(kind, payload)
            except Exception:  # a broken listener must not break firing
                log.exception("engine listener failed on %s", kind)

    # ------------------------------------------------------------------ compile

    def _compile(self, files: dict[str, str], label: str, on_progress: Callable[[int, int, str], None] | None = None,
                 warm: bool = True) -> CompiledRuleSet:
        """Incremental build (see gateway.engine.incremental), warmed before anyone fires it."""
        options = compiler.CompileOptions.from_settings(self.settings.engine)
        compiled = compiler.compile_cached(files, label, options, on_progress)
        if warm:
            warmup.warm(compiled, files, budget_s=self.settings.engine.warm_budget_s)
        return compiled

    def validate(self, name: str, files: dict[str, str],
                 on_progress: Callable[[int, int, str], None] | None = None) -> list[CompileError]:
        """All compile errors of ``files`` ([] when they compile). Deploys nothing.

        ``on_progress(done, total, stage)`` follows the build (see compiler.compile_files)."""
        check_name(name)
        try:
            self._compile(files, name, on_progress, warm=False)
        except CompileFailed as failed:
            return failed.errors
        return []

    def expand(self, name: str, files: dict[str, str]) -> dict[str, str]:
        """The DRL each ``.dslr`` file expands to."""
        check_name(name)
        return compiler.expand(files)

    # ------------------------------------------------------------------ versions

    def _live_entry(self, name: str) -> tuple[VersionInfo, CompiledRuleSet]:
        entry = self._live.get(name)
        if entry is not None:
            return entry
        with self._lock:
            entry = self._live.get(name)
            if entry is not None:
                return entry
            state = self.store.state(name)
            if state.current is None or state.deleted:
                raise RuleSetNotFound(name)
            stored = self.store.load(name, state.current)
            entry = (stored.info, self._compile(stored.files, name))
            self._live[name] = entry
            return entry

    def _names(self) -> list[str]:
        return [n for n in self.store.names() if not self.store.state(n).deleted and self.store.state(n).current]

    def list_rulesets(self) -> list[VersionInfo]:
        out = []
        for name in self._names():
            state = self.store.state(name)
            out.append(self.store.info(name, state.current))  # type: ignore[arg-type]
        return out

    def current(self, name: str) -> RuleSetVersion:
        check_name(name)
        state = self.store.state(name)
        if state.current is None or state.deleted:
            raise RuleSetNotFound(name)
        return self.store.load(name, state.current)

    def versions(self, name: str) -> list[VersionInfo]:
        check_name(name)
        infos = self.store.list_versions(name)
        if not infos:
            raise RuleSetNotFound(name)
        return infos

    def version(self, name: str, version: int) -> RuleSetVersion:
        check_name(name)
        if not self.store.version_numbers(name):
            raise RuleSetNotFound(name)
        return self.store.load(name, int(version))

    def history(self, name: str) -> list[dict[str, Any]]:
        check_name(name)
        return self.store.history(name)

    def deploy(
        self,
        name: str,
        files: dict[str, str],
        author: str = "anonymous",
        comment: str = "",
        base_version: int | None = None,
    ) -> VersionInfo:
        """Compiles ``files`` and, only if that succeeds, makes them the live version of ``name``.

        ``base_version`` is the version the author's edit started from: if someone deployed in
        between, :class:`VersionConflict` is raised and nothing changes.
        """
        check_name(name)
        started = time.perf_counter()
        compiled = self._compile(files, name)
        with self._lock:
            state = self.store.state(name)
            current = None if state.deleted else state.current
            if base_version is not None and int(base_version) != (current or 0):
                raise VersionConflict(name, int(base_version), current or 0)
            info = self.store.save_version(name, files, author, comment, compiled.hash)
            self.store.set_state(name, info.version)
            self._live[name] = (info, compiled)
            self.store.append_history(name, {"event": "deploy", "version": info.version, "author": author, "comment": comment})
        elapsed = (time.perf_counter() - started) * 1000
        log.info("deployed %s version %d (%d rules) in %.0f ms", name, info.version, compiled.rule_count, elapsed)
        self._notify("deploy", {**info.to_dict(), "rules": compiled.rule_count, "duration_ms": elapsed})
        return info

    def rollback(self, name: str, version: int, author: str = "anonymous", comment: str = "") -> VersionInfo:
        """Makes an earlier (or any stored) version live again; history keeps the rollback."""
        check_name(name)
        stored = self.version(name, int(version))
        compiled = self._compile(stored.files, name)
        with self._lock:
            self.store.set_state(name, stored.info.version)
            self._live[name] = (stored.info, compiled)
            self.store.append_history(name, {"event": "rollback", "version": stored.info.version, "author": author, "comment": comment})
        self._notify("rollback", {**stored.info.to_dict(), "by": author})
        return stored.info

    def delete(self, name: str, author: str = "anonymous") -> None:
        """Stops serving ``name``. Its versions stay stored; a new deploy continues the numbering."""
        check_name(name)
        with self._lock:
            state = self.store.state(name)
            if state.current is None or state.deleted:
                raise RuleSetNotFound(name)
            self.store.set_state(name, None, deleted=True)
            self._live.pop(name, None)
            self.store.append_history(name, {"event": "delete", "author": author})
            for session in [s for s in self._sessions.values() if s.ruleset == name]:
                self.close_session(session.id)
        self._notify("delete", {"name": name, "by": author})

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
    ) -> FireResult:
        """Fires the live version of ``name`` on ``facts`` in a fresh session (stateless).

        ``context`` (e.g. ``{"origin": "ros", "customers": [...]}``) is passed on to listeners, so
        the Information State and the decision log can say where a decision came from.
        """
        info, compiled = self._live_entry(name)
        result = self._fire(compiled, name, info.version, facts, fire_limit, return_facts, record_facts)
        if self._listeners:
            payload = {"ruleset": name, "version": info.version, "facts": facts, **_summary(result)}
            if context:
                payload["context"] = context
            self._notify("fire", payload)
        return result

    def fire_files(self, files: dict[str, str], facts: list[dict[str, Any]], fire_limit: int | None = None) -> FireResult:
        """Fires undeployed text (the workbench's "try it"): compile errors raise CompileFailed."""
        compiled = self._compile(files, "draft")
        return self._fire(compiled, DRAFT, 0, facts, fire_limit, True, True)

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
        facts_json = encode_facts(facts, self.settings.engine.max_facts)
        limit = int(fire_limit or self.settings.engine.fire_limit)
        started = time.perf_counter()
        answer = str(compiled.runner.fire(facts_json, limit, return_facts, record_facts))
        return decode_result(answer, name, version, (time.perf_counter() - started) * 1000)

    # ------------------------------------------------------------------ sessions

    def open_session(self, name: str, record_facts: bool = True) -> StatefulSession:
        """A long-lived stateful session on the live version of ``name``."""
        info, compiled = self._live_entry(name)
        java = jvm.helper_class("Session")(compiled.runner, record_facts)
        session = StatefulSession(
            java, name, info.version, self.settings.engine.fire_limit, self.settings.engine.max_facts,
            on_close=self._forget_session,
        )
        with self._lock:
            self._sessions[session.id] = session
        return session

    def get_session(self, session_id: str) -> StatefulSession:
        session = self._sessions.get(session_id)
        if session is None:
            raise EngineError(f"no open session '{session_id}'")
        return session

    def sessions(self) -> list[StatefulSession]:
        return list(self._sessions.values())

    def close_session(self, session_id: str) -> None:
        with self._lock:
            session = self._sessions.pop(session_id, None)
        if session is not None:
            session.close()

    def _forget_session(self, session_id: str) -> None:
        with self._lock:
            self._sessions.pop(session_id, None)

    # ------------------------------------------------------------------ warm-up

    def warm_up(self, rounds: int = 2, fires: int = 200, background: bool = True) -> threading.Thread | None:
        """Builds a small rule set ``rounds`` times (results thrown away) and fires each live rule set
        ``fires`` times with its ``examples.json`` facts (or none), so the JIT has compiled Drools'
        builder and firing paths before an author's first live edit or the first customer: the
        first firings in a fresh JVM are ~100x slower. Runs in a daemon thread by default.
        (Not the live sets themselves: with incremental builds they would come from the cache, and
        compiling a 10,000-rule set twice at start would cost minutes.)
        """

        def work() -> None:
            try:
                compiler.warm_builder(rounds)
            except Exception:  # best effort, as below
                log.debug("warm-up of the builder failed", exc_info=True)
            for info in self.list_rulesets():
                try:
                    stored = self.store.load(info.name, info.version)
                    _, compiled = self._live_entry(info.name)
                    samples = _example_fact_sets(stored.files) or [[]]
                    for k in range(fires):  # not through fire(): warm-up is no decision to log
                        try:
                            self._fire(compiled, info.name, info.version, samples[k % len(samples)], None, False, True)
                        except EngineError:
                            samples = [[]]
                except Exception:  # warm-up is best effort; real errors show on real use
                    log.debug("warm-up of %s failed", info.name, exc_info=True)

        if not background:
            work()
            return None
        thread = threading.Thread(target=work, name="engine-warm-up", daemon=True)
        thread.start()
        return thread

    # ------------------------------------------------------------------ files on disk

    def load_rules_dir(self, rules_dir: str | None = None) -> dict[str, str]:
        """Deploys each ``<rules_dir>/<name>/`` folder whose content is not stored yet.

        A folder that does not compile is reported and skipped: the stored version keeps serving.
        Returns ``{name: "deployed v3" | "unchanged v2" | "failed: …"}``.
        """
        root = Path(rules_dir or self.settings.engine.rules_dir)
        report: dict[str, str] = {}
        if not root.is_dir():
            log.warning("rules directory %s does not exist", root)
            return report
        for folder in sorted(p for p in root.iterdir() if p.is_dir()):
            report[folder.name] = self._load_folder(folder)
        return report

    def _load_folder(self, folder: Path) -> str:
        name = folder.name
        try:
            check_name(name)
            files = read_folder(folder)
        except (InvalidRuleSet, OSError, UnicodeDecodeError) as exc:
            log.error("skipping rules folder %s: %s", folder, exc)
            return f"failed: {exc}"
        if not files:
            return "skipped: no rule files"
        digest = content_hash(files)
        stored = self.store.list_versions(name)
        state = self.store.state(name)
        if stored and stored[-1].hash == digest:
            if state.deleted:
                return "deleted (unchanged on disk)"
            self._live_entry(name)  # compile the serving version now, not on the first request
            return f"unchanged v{state.current}"
        try:
            info = self.deploy(name, files, author="filesystem", comment=f"loaded from {folder}")
        except CompileFailed as failed:
            for err in failed.errors:
                log.error("%s/%s", folder, err)
            return f"failed: {failed}"
        return f"deployed v{info.version}"


def _example_fact_sets(files: dict[str, str]) -> list[list[dict[str, Any]]]:
    """The fact lists of a rule set's ``examples.json`` ([{"name", "facts"}]), [] if none/unreadable."""
    try:
        examples = json.loads(files.get("examples.json", "[]"))
        return [e["facts"] for e in examples if isinstance(e, dict) and isinstance(e.get("facts"), list)]
    except (ValueError, TypeError, KeyError):
        return []


def _summary(result: FireResult) -> dict[str, Any]:
    return {
        "actions": result.actions,
        "fired": [f["rule"] for f in result.fired],
        "fire_count": result.fire_count,
        "duration_ms": result.duration_ms,
    }
