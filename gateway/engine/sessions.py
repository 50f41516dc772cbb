"""The live stateful sessions of this process: one registry for the KIE endpoint, the REST API
and the stream bindings.

Why one place: a session is a resource clients hold across calls — a KIE ``lookup`` of a
declared ksession must reach the same live session as ``/api/rulesets/{name}/sessions/{id}``, and
what happens to it on a deploy, after idling, or at a limit must be the same whoever opened it.

- **Declared sessions** (a rule set's ``kmodule.xml`` ksessions, or KIE's defaults): a stateful one
  has one live instance per rule set, created on first use and addressed by its name
  (``defaultKieSession``); a stateless one is a fresh session per call (nothing kept here).
- **Opened sessions** (``POST …/sessions``): addressed by a generated id (or the client's).
- **Stream bindings' sessions** (:meth:`SessionManager.binding_session`): a stateful binding's
  session under the stable id ``stream.<query>``, durable and claimed like a conversation, living
  as long as its binding (no idle TTL); a process that stops puts it away (:meth:`put_away`).
- **Deploy policy**: ``follow`` (the default, ``sessions.on_deploy``) moves a session to each new
  version with its facts and fact handles, like ``KieContainer.updateToVersion`` (see
  :meth:`StatefulSession.move_to`); ``pin`` keeps it on the version it was opened on. A session
  whose facts do not fit the new version stays where it is and says why. Deleting the rule set
  disposes its sessions (its history stays).
- **Limits**: sessions per rule set, facts per session, and an idle TTL after which a
  conversation's session is disposed (stream-bound sessions live as long as their binding).
- **Across processes**: a session lives in the process that created it. With a ``directory``
  (:class:`gateway.store.session_records.SessionDirectory`), creating one claims it in the
  Information State, and asking for a session another process owns raises
  :class:`SessionElsewhere` — the REST layer forwards the call to that owner.
- **Durable** (``sessions.durable``, with a ``log``: :mod:`gateway.engine.durable`): a conversation
  session's commands are journalled; when its owner is gone (or after a restart) the next call
  claims it (a compare-and-set on its record) and rebuilds it here from its snapshots and log.
"""

from __future__ import annotations

import collections
import itertools
import logging
import os
import re
import threading
import time
from typing import Any, Protocol

from gateway.engine import compiler, durable
from gateway.engine.errors import EngineError
from gateway.engine.kmodule import Declarations, SessionDeclaration
from gateway.engine.session import CommandFailed, StatefulSession

log = logging.getLogger(__name__)

CONVERSATION_KINDS = ("kie", "rest")  # sessions clients hold: counted in limits, reaped when idle
STREAM_KIND = "stream"  # a stream binding's session: durable and claimed like a conversation, lives with its binding
ID_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.:-]{0,127}$")
#: Sessions disposed in this process that it remembers (see SessionManager._disposed_here).
DISPOSED_REMEMBERED = 10_000
_ids = itertools.count(1)


class SessionNotFound(EngineError):
    """No such session (never opened, disposed, or reaped after idling)."""

    kind = "session"


class SessionRefused(EngineError):
    """A session cannot be opened as asked (a bad id, a stateless ksession, one already open)."""

    kind = "session"

    def __init__(self, message: str, conflict: bool = False) -> None:
        super().__init__(message)
        self.conflict = conflict


class SessionLimit(EngineError):
    """A limit on sessions per rule set or facts per session would be exceeded."""

    kind = "limit"


class SessionElsewhere(EngineError):
    """The session lives in another gateway process (``owner``: its record in the directory)."""

    kind = "elsewhere"

    def __init__(self, ruleset: str, session_id: str, owner: dict[str, Any]) -> None:
        super().__init__(f"session {session_id} of {ruleset} lives in process {owner.get('process')}")
        self.ruleset, self.session_id, self.owner = ruleset, session_id, owner


class SessionGone(EngineError):
    """The session's owner process is gone, and the session (with its facts) with it."""

    kind = "gone"


class Directory(Protocol):
    """Where sessions are recorded across processes (the Information State's ``sessions``)."""

    process: str

    def claim(self, ruleset: str, session_id: str, info: dict[str, Any]) -> dict[str, Any]:
        """Records this process as the owner unless another one is; returns the owner record."""

    def owner(self, ruleset: str, session_id: str) -> dict[str, Any] | None: ...

    def release(self, ruleset: str, session_id: str) -> None: ...

    def records(self, ruleset: str | None = None) -> list[dict[str, Any]]: ...

    def take(self, ruleset: str, session_id: str, dead: str, info: dict[str, Any]) -> bool:
        """Compare-and-set: records this process as the owner if ``dead`` still is; True if it won."""

    def alive(self, record: dict[str, Any]) -> bool:
        """Whether the process an owner record names is alive."""


class SessionManager:
    """The sessions of one engine (thread-safe). Built by :class:`gateway.engine.Engine`."""

    def __init__(self, engine: Any, settings: Any) -> None:
        self.engine = engine
        self.settings = settings  # gateway.config.SessionSettings
        self.directory: Directory | None = None
        self.log: durable.SessionLog | None = None  # durable sessions' log (gateway.runtime.session_log)
        self._rebuilding: set[tuple[str, str]] = set()
        # claimed here and being made (its record is ours, the session not registered yet): a call
        # for it meanwhile must not take the record for a leftover and release it
        self._opening: set[tuple[str, str]] = set()
        # Sessions this process disposed (or reaped), newest last, bounded: their tombstone may not
        # have reached the Information State yet, so without this the next lookup of a declared
        # ksession after a `dispose` would wait for the journal to catch up (a 503 under load)
        # only to learn what this process already knows. One that fell off is looked up the slow way.
        self._disposed_here: collections.OrderedDict[tuple[str, str], None] = collections.OrderedDict()
        # Owners forwarding found dead (and released the record of), bounded: the call is then run
        # again here, finds no owner, and its rebuild must still wait for that process's journal
        # (see owner_gone). One that fell off waits for every dead writer's journal all the same.
        self._gone_owners: collections.OrderedDict[tuple[str, str], str] = collections.OrderedDict()
        self._sessions: dict[tuple[str, str], StatefulSession] = {}
        self._lock = threading.RLock()
        self._creating: dict[tuple[str, str], threading.Lock] = {}
        self._keeping: set[tuple[str, str]] = set()  # closed by put_away: their logs stay
        self._follow_lock = threading.Lock()  # a deploy and the follower's sync of it move a session once
        self._reaper: threading.Thread | None = None
        self._stop = threading.Event()

    # ------------------------------------------------------------------ declarations

    def declarations(self, ruleset: str) -> Declarations:
        return self.engine.declared_sessions(ruleset)

    def resolve_lookup(self, ruleset: str, lookup: str | None) -> SessionDeclaration:
        """The declared session a KIE batch's ``lookup`` names (None: the default one, see
        ``sessions.no_lookup``); :class:`SessionNotFound` in KIE's words when there is none."""
        declared = self.declarations(ruleset)
        if lookup:
            found = declared.get(lookup)
            if found is None:
                raise SessionNotFound(f"Session '{lookup}' not found on container '{ruleset}' "
                                      f"(its sessions: {', '.join(declared.names()) or 'none'})")
            return found
        order = (False, True) if self.settings.no_lookup == "stateless" else (True, False)
        for stateful in order:
            found = declared.default(stateful)
            if found is not None:
                return found
        raise SessionNotFound(f"No default KieSession found on container '{ruleset}'.")

    # ------------------------------------------------------------------ opening

    def open(self, ruleset: str, *, session_id: str | None = None, kind: str = "rest", clock: str | None = None,
             on_deploy: str | None = None, record_facts: bool = True, durable_: bool | None = None) -> StatefulSession:
        """Opens a session on the live version of ``ruleset``. ``session_id`` names a declared
        stateful ksession (its clock and policy come from the declaration) or, for REST, any
        free id; None generates one."""
        declared: SessionDeclaration | None = None
        if session_id is not None:
            if not ID_PATTERN.match(session_id):
                raise SessionRefused(f"invalid session id {session_id!r}: 1-128 letters, digits, '_', '.', ':' or '-'")
            declared = self.declarations(ruleset).get(session_id)
            if declared is not None and not declared.stateful:
                raise SessionRefused(f"session '{session_id}' of {ruleset} is declared stateless: it keeps nothing to open")
        key = (ruleset, session_id or "")
        with self._lock:
            if session_id is not None and key in self._sessions:
                raise SessionRefused(f"session '{session_id}' of {ruleset} is already open", conflict=True)
            if kind in CONVERSATION_KINDS:
                self._check_session_limit(ruleset)
        if session_id is not None and kind == "rest":
            self._refuse_if_stored(ruleset, session_id)
        sid = session_id or self._new_id()
        clock = clock or (declared.clock if declared else "pseudo")
        policy = on_deploy or (declared.on_deploy if declared and declared.on_deploy else self.settings.on_deploy)
        # claimed (and durable when sessions are): conversations, and a stream binding's session under
        # its stable id (binding_session); a stream session opened without an id (open_session) stays ours
        claims = kind in CONVERSATION_KINDS or (kind == STREAM_KIND and session_id is not None)
        with self._lock:
            self._opening.add((ruleset, sid))
        try:
            session = self._make(ruleset, sid, kind, clock, policy, record_facts, durable_, claims)
            with self._lock:
                self._sessions[(ruleset, sid)] = session
                self._disposed_here.pop((ruleset, sid), None)
        finally:
            with self._lock:
                self._opening.discard((ruleset, sid))
        self._ensure_reaper()
        return session

    def _make(self, ruleset: str, sid: str, kind: str, clock: str, policy: str, record_facts: bool,
              durable_: bool | None, claims: bool) -> StatefulSession:
        """Claims (when the session is one that is) and makes a session; :meth:`open` registers it."""
        if self.directory is not None and claims:
            owner = self.directory.claim(ruleset, sid, {"kind": kind, "clock": clock, "on_deploy": policy})
            if owner.get("process") != self.directory.process:
                raise SessionElsewhere(ruleset, sid, owner)
        try:
            session = self.engine.new_session(ruleset, sid, clock=clock, on_deploy=policy, kind=kind,
                                              record_facts=record_facts,
                                              on_close=lambda _id, r=ruleset, s=sid: self._forget(r, s))
        except Exception:
            if self.directory is not None and claims:
                self.directory.release(ruleset, sid)  # claimed, never made
            raise
        if claims:
            session.fact_limit = self.settings.max_facts
            keep = self.settings.durable if durable_ is None else durable_
            if keep and self.log is not None:
                self._make_durable(session, record_facts)
        return session

    def _refuse_if_stored(self, ruleset: str, session_id: str) -> None:
        """A create naming an id that a durable session keeps in the log (its process restarted
        or died, and nobody has used it since) is a conflict, as for a live one: opening a new
        session under it would hide the stored one's facts from its clients."""
        if self.log is None or (ruleset, session_id) in self._disposed_here:
            return
        if self.log.stored(ruleset, session_id):
            raise SessionRefused(f"session '{session_id}' of {ruleset} already exists: it is a durable session kept in the "
                                 "Information State (its process stopped or died), rebuilt on its next call; use it, or "
                                 "dispose it first", conflict=True)

    # ------------------------------------------------------------------ durable sessions

    def attach_log(self, session_log: durable.SessionLog) -> None:
        """Makes conversation sessions durable in ``session_log``; the reaper starts now, to clean
        up stored sessions nobody used since their process went."""
        self.log = session_log
        self._ensure_reaper()

    def _make_durable(self, session: StatefulSession, record_facts: bool) -> None:
        """Journals the opening of ``session`` (before its create is answered) and keeps it durable."""
        assert self.log is not None
        epoch = f"{os.getpid():x}-{time.time_ns():x}-{next(_ids)}"
        state = durable.Durability(self.log, session.ruleset, session.id, epoch, every=self.settings.snapshot_every,
                                   interval_s=self.settings.snapshot_interval_s, shared_within_s=self._shared_within())
        try:
            state.open({"version": session.version, "clock": session.clock, "on_deploy": session.on_deploy,
                        "session_kind": session.kind, "record_facts": record_facts})
        except Exception as exc:
            session.close()
            raise durable.JournalRefused(f"session {session.id} of {session.ruleset} could not be journalled "
                                         f"({exc}): not opened; retry later") from None
        session.durability = state
        session.rebuilder = lambda r=session.ruleset, s=session.id: self._rebuild(r, s)[1]

    def _shared_within(self) -> float | None:
        """``sessions.ack_after: database``: how long a command may wait to reach the database."""
        return self.settings.rebuild_timeout_s if self.settings.ack_after == "database" else None

    def _rebuild(self, ruleset: str, session_id: str, gone: str | None = None) -> tuple[durable.History, durable.Rebuilt]:
        """The session as its log says (see :func:`durable.rebuild`); SessionNotFound if none is kept."""
        assert self.log is not None
        history = self.log.history(ruleset, session_id, gone)
        if history is None or history.disposed:
            raise SessionNotFound(f"no session '{session_id}' on rule set {ruleset} (disposed, idle longer than "
                                  f"{self.settings.idle_ttl_s:g} s, or never opened)")
        builder = _Builder(self.engine, ruleset, history.opening)
        return history, durable.rebuild(history, builder, self.engine.settings.engine.fire_limit, ruleset, session_id)

    def _stored(self, ruleset: str, session_id: str) -> StatefulSession | None:
        """A session not in this process: :class:`SessionElsewhere` while its owner lives; else
        rebuilt here from its log (claimed first: one process wins, the others forward to it), or
        :class:`SessionGone` (its owner died and it was not durable), or None (no such session)."""
        with self._lock:
            live = self.find(ruleset, session_id)
            if live is not None:  # opened (or rebuilt) here since the caller looked: its record is ours
                return live
            if (ruleset, session_id) in self._rebuilding:  # claimed by us, being rebuilt: its record is ours
                raise durable.Rebuilding(f"session {session_id} of {ruleset} is being rebuilt here: retry")
            if (ruleset, session_id) in self._opening:  # claimed by us, being opened: its record is ours
                raise durable.Rebuilding(f"session {session_id} of {ruleset} is being opened here: retry")
        owner = self.directory.owner(ruleset, session_id) if self.directory is not None else None
        if owner is not None and self.directory is not None and owner.get("process") != self.directory.process:
            if self.log is None or self.directory.alive(owner):
                raise SessionElsewhere(ruleset, session_id, owner)
            return self._recover(ruleset, session_id, owner)
        if owner is not None and self.directory is not None:  # recorded as ours but not here: disposed under the record
            self.directory.release(ruleset, session_id)
        if self.log is None or (ruleset, session_id) in self._disposed_here:
            return None  # disposed here: nothing to rebuild, and no need to wait for the journal to say so
        with self._lock:
            gone = self._gone_owners.get((ruleset, session_id))  # kept until a rebuild succeeds (a 503 is retried)
        return self._recover(ruleset, session_id, None, gone)

    def owner_gone(self, ruleset: str, session_id: str, process: str) -> None:
        """Forwarding found the session's owner ``process`` dead and released its record; the call
        is run again here and rebuilds the session. Its rebuild must read every entry that process
        acknowledged, so it waits for that process's journal (named by its pid on this host) to be
        in the Information State, whoever ships it (issue 28)."""
        with self._lock:
            self._gone_owners[(ruleset, session_id)] = process
            self._gone_owners.move_to_end((ruleset, session_id))
            while len(self._gone_owners) > DISPOSED_REMEMBERED:
                self._gone_owners.popitem(last=False)

    def _recover(self, ruleset: str, session_id: str, dead: dict[str, Any] | None,
                 gone_process: str | None = None) -> StatefulSession | None:
        """Claims the session (a compare-and-set on its owner record, ``dead``'s if one is still
        recorded) and rebuilds it from its log, once the journal of the process it was taken from
        (``dead``, or ``gone_process`` whose record forwarding released) is in; callers meanwhile
        get :class:`durable.Rebuilding` (503, retry)."""
        key = (ruleset, session_id)
        with self._lock:
            if key in self._rebuilding:
                raise durable.Rebuilding(f"session {session_id} of {ruleset} is being rebuilt here: retry")
            self._rebuilding.add(key)
        claimed = False
        try:
            assert self.log is not None
            gone = str(dead.get("process")) if dead is not None else gone_process
            history = self.log.history(ruleset, session_id, gone)
            if history is None or history.disposed:
                if dead is not None and self.directory is not None:
                    self.directory.release(ruleset, session_id, process=dead.get("process"))
                    raise SessionGone(f"session {session_id} of {ruleset} lived in gateway process {dead.get('process')}, "
                                      "which is gone, and it was not durable: its facts are lost. Open a new session.")
                return None
            claimed = self._claim(ruleset, session_id, dead, history.opening)
            _, rebuilt = self._rebuild(ruleset, session_id, gone)  # read again, now that it is ours
            session = self._wrap(ruleset, session_id, history.opening, rebuilt)
            with self._lock:
                live = self.find(ruleset, session_id)
                raced = live is not None or key in self._opening
                if not raced:
                    self._sessions[key] = session
                    self._gone_owners.pop(key, None)
            if raced:  # opened here meanwhile: that one is the session (and its record), this copy goes
                claimed = False
                rebuilt.java.dispose()
                if live is None:
                    raise durable.Rebuilding(f"session {session_id} of {ruleset} is being opened here: retry")
                return live
            log.warning("session %s of %s rebuilt here at command %d (version %d, %d facts)%s", session_id, ruleset,
                     rebuilt.seq, rebuilt.version, session.fact_count,
                     f", taken over from {gone}" if gone else "")
        except SessionElsewhere:
            raise
        except BaseException:
            if claimed and self.directory is not None:
                self.directory.release(ruleset, session_id)
            raise
        finally:
            with self._lock:
                self._rebuilding.discard(key)
        self._ensure_reaper()
        if session.on_deploy == "follow":
            self.follow(ruleset)  # a version deployed while nobody held it
        return session

    def _claim(self, ruleset: str, session_id: str, dead: dict[str, Any] | None, opening: dict[str, Any]) -> bool:
        """Records this process as the owner: exactly one process wins; :class:`SessionElsewhere`
        (the winner) for the others. True if a record was written (released if the rebuild fails)."""
        if self.directory is None:
            return False
        info = {"kind": opening.get("session_kind"), "clock": opening.get("clock"), "on_deploy": opening.get("on_deploy")}
        if dead is not None:
            if self.directory.take(ruleset, session_id, str(dead.get("process")), info):
                return True
        else:
            owner = self.directory.claim(ruleset, session_id, info)
            if owner.get("process") == self.directory.process:
                return True
        owner = self.directory.owner(ruleset, session_id)
        if owner is None:
            raise durable.Rebuilding(f"session {session_id} of {ruleset} is changing owner: retry")
        raise SessionElsewhere(ruleset, session_id, owner)

    def _wrap(self, ruleset: str, session_id: str, opening: dict[str, Any], rebuilt: durable.Rebuilt) -> StatefulSession:
        assert self.log is not None
        session = self.engine.wrap_session(rebuilt.java, ruleset, rebuilt.version, session_id, clock=str(opening["clock"]),
                                           on_deploy=str(opening["on_deploy"]), kind=str(opening["session_kind"]),
                                           record_facts=bool(opening.get("record_facts", True)),
                                           on_close=lambda _id, r=ruleset, s=session_id: self._forget(r, s))
        session.fact_limit = self.settings.max_facts
        session.durability = durable.Durability(self.log, ruleset, session_id, str(opening["epoch"]),
                                                every=self.settings.snapshot_every,
                                                interval_s=self.settings.snapshot_interval_s, seq=rebuilt.seq,
                                                snapshot_seq=rebuilt.snapshot_seq, last_snapshot=rebuilt.last_snapshot,
                                                shared_within_s=self._shared_within())
        session.rebuilder = lambda: self._rebuild(ruleset, session_id)[1]
        return session

    def lookup(self, ruleset: str, lookup: str | None) -> tuple[SessionDeclaration, StatefulSession | None]:
        """A KIE batch's session: the declaration, and for a stateful one its live session (made
        on first use); None for a stateless one (the caller fires a throwaway session)."""
        declared = self.resolve_lookup(ruleset, lookup)
        if not declared.stateful:
            return declared, None
        return declared, self.named(ruleset, declared.name)

    def named(self, ruleset: str, name: str) -> StatefulSession:
        """The live session of declared stateful ksession ``name`` (created on first use)."""
        key = (ruleset, name)
        session = self._sessions.get(key)
        if session is not None and not session.closed:
            return session
        with self._lock:
            gate = self._creating.setdefault(key, threading.Lock())
        with gate:  # two first calls at once make one session
            session = self._sessions.get(key)
            if session is not None and not session.closed:
                return session
            stored = self._stored(ruleset, name)
            if stored is not None:
                return stored
            return self.open(ruleset, session_id=name, kind="kie")

    def binding_session(self, ruleset: str, session_id: str, *, on_deploy: str | None = None) -> StatefulSession:
        """A stream binding's session under its stable id: this process's, else rebuilt here from
        its log (after a restart, or taken over from a dead owner), else opened (durable when
        sessions are). :class:`SessionElsewhere` while another live process holds it."""
        key = (ruleset, session_id)
        session = self.find(ruleset, session_id)
        if session is not None:
            return session
        with self._lock:
            gate = self._creating.setdefault(key, threading.Lock())
        with gate:  # the binding's thread and a REST read at once make (or rebuild) one session
            session = self.find(ruleset, session_id)
            if session is not None:
                return session
            stored = self._stored(ruleset, session_id)
            if stored is not None:
                return stored
            return self.open(ruleset, session_id=session_id, kind=STREAM_KIND, clock="pseudo", on_deploy=on_deploy)

    def put_away(self, ruleset: str, session_id: str) -> None:
        """Closes this process's session but keeps its log and snapshots (a stream binding stopping
        with its process, or replaced by one with the same session): a restart or another process
        rebuilds it. A session that is not durable is simply closed."""
        session = self.find(ruleset, session_id)
        if session is None:
            return
        with self._lock:
            self._keeping.add((ruleset, session_id))
        try:
            session.close()
        finally:
            with self._lock:
                self._keeping.discard((ruleset, session_id))

    def _check_session_limit(self, ruleset: str) -> None:
        open_here = sum(1 for (r, _), s in self._sessions.items() if r == ruleset and s.kind in CONVERSATION_KINDS)
        limit = self.settings.max_per_ruleset
        if open_here >= limit:
            raise SessionLimit(f"rule set {ruleset} already has {open_here} open sessions (at most {limit}: "
                               f"sessions.max_per_ruleset); dispose one first")

    @staticmethod
    def _new_id() -> str:
        return f"s{os.getpid():x}-{int(time.time() * 1000):x}-{next(_ids)}"

    # ------------------------------------------------------------------ finding

    def find(self, ruleset: str, session_id: str) -> StatefulSession | None:
        session = self._sessions.get((ruleset, session_id))
        return session if session is not None and not session.closed else None

    def get(self, ruleset: str, session_id: str) -> StatefulSession:
        """This process's session, else :class:`SessionElsewhere` (another process owns it) or
        :class:`SessionNotFound`. A declared stateful ksession is created on first use."""
        session = self.find(ruleset, session_id)
        if session is not None:
            return session
        declared = self.declarations(ruleset).get(session_id)
        if declared is not None and declared.stateful:
            return self.named(ruleset, session_id)  # rebuilt, elsewhere, or made on first use
        stored = self._stored(ruleset, session_id)
        if stored is not None:
            return stored
        if declared is not None and declared.stateful:
            return self.named(ruleset, session_id)
        raise SessionNotFound(f"no session '{session_id}' on rule set {ruleset} (disposed, idle longer than "
                              f"{self.settings.idle_ttl_s:g} s, or never opened)")

    def list(self, ruleset: str | None = None) -> list[StatefulSession]:
        with self._lock:
            return [s for (r, _), s in self._sessions.items() if (ruleset is None or r == ruleset) and not s.closed]

    def by_id(self, session_id: str) -> StatefulSession | None:
        """Any rule set's session with this id (the engine's old ``get_session``)."""
        return next((s for (_, sid), s in list(self._sessions.items()) if sid == session_id), None)

    # ------------------------------------------------------------------ closing

    def dispose(self, ruleset: str, session_id: str) -> None:
        session = self.find(ruleset, session_id) or self.get(ruleset, session_id)  # elsewhere, or rebuilt to dispose
        session.close()

    def dispose_ruleset(self, ruleset: str) -> None:
        for session in self.list(ruleset):
            session.close()

    def close_all(self) -> None:
        self._stop.set()
        for session in self.list():
            try:
                session.close()
            except Exception:  # closing at shutdown is best effort
                log.debug("closing session %s failed", session.id, exc_info=True)

    def _forget(self, ruleset: str, session_id: str) -> None:
        with self._lock:
            session = self._sessions.pop((ruleset, session_id), None)
            self._creating.pop((ruleset, session_id), None)
            keep = (ruleset, session_id) in self._keeping
        if session is not None and session.durability is not None and self.log is not None and not self._stop.is_set() \
                and not keep:
            # disposed (or reaped): its log goes; closed at shutdown: it stays, for a restart or a takeover
            self.log.delete(ruleset, session_id, session.durability.epoch)
            self._remember_disposed((ruleset, session_id))
        if self.directory is not None:
            try:
                self.directory.release(ruleset, session_id)
            except Exception:  # the record is cleaned when this process's member record goes
                log.warning("could not release the record of session %s/%s", ruleset, session_id, exc_info=True)

    def _remember_disposed(self, key: tuple[str, str]) -> None:
        with self._lock:
            self._disposed_here[key] = None
            self._disposed_here.move_to_end(key)
            while len(self._disposed_here) > DISPOSED_REMEMBERED:
                self._disposed_here.popitem(last=False)

    # ------------------------------------------------------------------ deploys

    def on_engine_event(self, kind: str, payload: dict[str, Any]) -> None:
        """Engine listener: a new version of a rule set is live here (deploy, rollback, a sync
        from another process): move the sessions that follow it."""
        if kind in ("deploy", "rollback", "sync"):
            self.follow(str(payload.get("name")))

    def follow(self, ruleset: str) -> dict[str, str]:
        """Moves every ``follow`` session of ``ruleset`` to the live version; ``{id: outcome}``."""
        with self._follow_lock:
            return self._follow(ruleset)

    def _follow(self, ruleset: str) -> dict[str, str]:
        report: dict[str, str] = {}
        sessions = [s for s in self.list(ruleset) if s.on_deploy == "follow"]
        if not sessions:
            return report
        try:
            target = self.engine.live_compiled(ruleset)
        except EngineError:
            return report
        info, compiled = target
        for session in sessions:
            if session.version == info.version:
                continue
            try:
                unchanged = self.engine.unchanged_rules(ruleset, session.version, info.version)
                java = self.engine.new_java_session(compiled, session.clock, session.kind, session.record_facts)
                moved = session.move_to(compiled, info.version, unchanged, java)
            except Exception as exc:  # a move that fails leaves the session where it was
                log.exception("session %s of %s could not move to version %d", session.id, ruleset, info.version)
                session._stay(info.version, str(exc))
                moved = False
            report[session.id] = f"moved to v{info.version}" if moved else (session.pinned_reason or "stayed")
            (log.info if moved else log.warning)("session %s of %s: %s", session.id, ruleset, report[session.id])
        return report

    # ------------------------------------------------------------------ idle sessions

    def _ensure_reaper(self) -> None:
        if self._reaper is not None or self.settings.idle_ttl_s <= 0:
            return
        with self._lock:
            if self._reaper is None:
                self._reaper = threading.Thread(target=self._reap_loop, name="session-reaper", daemon=True)
                self._reaper.start()

    def _reap_loop(self) -> None:
        interval = max(0.05, min(self.settings.reap_interval_s, self.settings.idle_ttl_s / 2))
        while not self._stop.wait(interval):
            try:
                self.reap()
                self.reap_stored()
            except Exception:
                log.exception("reaping idle sessions failed")

    def reap_stored(self) -> list[str]:
        """Deletes the logs of durable sessions no live process holds that have been idle longer
        than ``sessions.idle_ttl_s`` (their process died or stopped, and nobody used them since)."""
        ttl = self.settings.idle_ttl_s
        if self.log is None or ttl <= 0:
            return []
        gone = []
        for opening in self.log.sessions():
            key = (str(opening["ruleset"]), str(opening["session"]))
            if opening.get("session_kind") == STREAM_KIND:
                continue  # lives as long as its binding (gateway.stream.subscriber), idle or not
            if key in self._sessions or time.time() - self.log.last_activity(opening) <= ttl:
                continue
            owner = self.directory.owner(*key) if self.directory is not None else None
            if owner is not None and self.directory is not None and self.directory.alive(owner):
                continue  # its owner holds it (and reaps it itself)
            log.info("stored session %s of %s idle past %.0f s: its log is deleted", key[1], key[0], ttl)
            self.log.delete(key[0], key[1], str(opening["epoch"]))
            gone.append(key[1])
        return gone

    def reap(self) -> list[str]:
        """Disposes conversation sessions idle longer than ``sessions.idle_ttl_s``."""
        ttl = self.settings.idle_ttl_s
        gone = []
        for session in self.list():
            if ttl > 0 and session.kind in CONVERSATION_KINDS and session.idle_s > ttl:
                log.info("session %s of %s idle for %.0f s: disposed", session.id, session.ruleset, session.idle_s)
                session.close()
                gone.append(session.id)
        return gone


class _Builder:
    """Fresh Java sessions of a durable session's rule set, at the versions its log names."""

    def __init__(self, engine: Any, ruleset: str, opening: dict[str, Any]) -> None:
        self.engine, self.ruleset = engine, ruleset
        self.clock = str(opening.get("clock", "pseudo"))
        self.kind = str(opening.get("session_kind", "rest"))
        self.record_facts = bool(opening.get("record_facts", True))

    def java_session(self, version: int) -> Any:
        return self.engine.new_java_session(self.engine.compiled_version(self.ruleset, version), self.clock, self.kind,
                                            self.record_facts)

    def unchanged_rules(self, old: int, new: int) -> list[str]:
        return list(self.engine.unchanged_rules(self.ruleset, old, new))


# A top-level DRL unit starts a line: a rule (its name), or what ends the rule before it.
_UNIT_HEAD = re.compile(r"""^[ \t]*(rule|query|declare|function|import|global|package|dialect)\b[ \t]*"""
                        r"""("(?:[^"\\]|\\.)*"|'[^']*'|[^\s"']+)?""", re.MULTILINE)
_END = re.compile(r"\bend\b")
_COMMENT = re.compile(r"//[^\n]*|/\*.*?\*/", re.DOTALL)


def rule_texts(files: dict[str, str]) -> list[str]:
    """The DRL texts of a version's ``files``, its DSL/DSLR and decision tables expanded (for
    :func:`rule_fingerprints`); a version that no longer expands gives only its DRL, so its other
    rules count as changed."""
    texts = [text for fname, text in files.items() if fname.endswith(".drl")]
    try:
        texts.extend(compiler.expand(files).values())
    except EngineError:
        pass
    return texts


def rule_fingerprints(drl_texts: list[str]) -> dict[str, str]:
    """Rule name -> its text with comments and spacing normalised (to tell unchanged rules).

    A rule's text runs from its ``rule`` line to the last ``end`` before the next top-level unit:
    a rule written on one line (``rule "r" when … then … end``) is one rule too, where matching up
    to an ``end`` at the start of a line took it with the next rule's text (so it counted as changed
    by every edit of its neighbour, and its fired matches fired again after each such move)."""
    import hashlib

    out: dict[str, str] = {}
    for text in drl_texts:
        clean = _COMMENT.sub(" ", text)
        heads = list(_UNIT_HEAD.finditer(clean))
        for i, head in enumerate(heads):
            if head.group(1) != "rule" or not head.group(2):
                continue
            body = clean[head.start(): heads[i + 1].start() if i + 1 < len(heads) else len(clean)]
            ends = list(_END.finditer(body))
            if ends:
                body = body[: ends[-1].end()]
            out[head.group(2).strip("\"'")] = hashlib.sha256(" ".join(body.split()).encode()).hexdigest()
    return out


__all__ = ["CommandFailed", "Directory", "SessionElsewhere", "SessionGone", "SessionLimit", "SessionManager",
           "SessionNotFound", "SessionRefused", "rule_fingerprints"]
