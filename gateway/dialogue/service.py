"""The dialogue service: one turn of a conversation at a table, in and out.

Why a service of its own (built once, in :func:`gateway.app.build_gateway`): a conversation is
state kept across turns — a stateful session of the dialogue rule set per conversation (one per
table), whose ``Conversation`` fact holds the order's slots and the state — and a turn touches
the recogniser, the rules, the decision record, the robots and the Information State's ``orders``.
The REST route, the ROS ``Utterance`` topic and the ``take_order`` workflow all come here.

Where a conversation lives: in the Information State (:mod:`gateway.dialogue.records`), not in
the process of its first turn. Each turn reads the conversation's record, runs in this process's
session of it (made again from the record's facts when another process took the turn before, or
this one restarted), and writes the outcome only over the record it read; so any worker or host
continues any conversation, including one whose process was killed.

A turn: the words (text, or WAV audio through :class:`~gateway.dialogue.speech.Recogniser`)
become one ``Utterance`` fact (:func:`~gateway.dialogue.words.hear`); the rules understand it,
change the conversation and answer; the answer's ``{drink}``/``{drinks}``/``{cups}`` are filled
in; the turn is one recorded decision; Pepper's ``say`` actions go to the action router; a
completed order (the rules' ``order`` action) is kept in ``orders`` and handed to listeners (the
ROS topic ``/teahouse/orders``). A conversation silent for ``dialogue.silence_check_s`` is told so
(a ``Silence`` fact): the rules decide whether it ends.
"""

from __future__ import annotations

import collections
import copy
import logging
import os
import socket
import threading
import time
import uuid
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any, Callable

from gateway.config import DialogueSettings
from gateway.dialogue.grammar import Grammar, build
from gateway.dialogue.menu import Menu, read_menu
from gateway.dialogue.records import ConversationRecords, MemoryConversations, MongoConversations, RecordsUnavailable
from gateway.dialogue.speech import Recogniser, read_wav
from gateway.dialogue.words import hear
from gateway.engine.errors import EngineError
from gateway.engine.sessions import ID_PATTERN

log = logging.getLogger(__name__)

ORDERS = "orders"
FINISHED = ("ordered", "ended")  # a conversation in these states takes no more turns: the next one starts anew
ROBOT_MODULES = ("say", "move", "gesture")
WRITE_ATTEMPTS = 8  # a turn run again on a newer state at most this often before 503 (say it again)
ORPHAN_ORDER_S = 30.0  # an order written but not kept this long ago: its process died in between


class DialogueRefused(ValueError):
    """A turn refused as asked (bad conversation id, neither or both of text and audio, bad audio):
    ``field`` names what is wrong; nothing changed."""

    def __init__(self, field_name: str, message: str) -> None:
        super().__init__(message)
        self.field, self.message = field_name, message


class StateUnfit(RuntimeError):
    """A conversation's kept facts cannot be inserted into a session of the live rules."""


class DialogueBusy(RuntimeError):
    """Too many turns at once (``status`` 503) or conversations going on (429): try again later."""

    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


@dataclass
class Local:
    """This process's session of a conversation: valid while the record's ``rev`` is ``rev``
    (another process may have taken a turn since; then the session is made again from the record)."""

    conversation: str
    session: Any
    rev: int
    doc: dict[str, Any]  # the record as this process last wrote it
    used_at: float = field(default_factory=time.monotonic)


@dataclass
class Turn:
    """One committed change of a conversation: its record as written and what the rules did."""

    doc: dict[str, Any]
    changes: dict[str, Any]  # the fields the turn set (the rest of ``doc`` as read)
    result: Any
    fact: dict[str, Any]
    session: Any


class DialogueService:
    """Turns of conversations (see the module docstring). Thread-safe; any number of processes
    over one Information State continue the same conversations."""

    def __init__(self, engine: Any, knowledge: Any, settings: DialogueSettings, *, store: Any = None,
                 dispatch: Callable[[dict[str, Any]], None] | None = None,
                 records: ConversationRecords | None = None) -> None:
        self.engine = engine
        self.knowledge = knowledge
        self.settings = settings
        self.store = store
        self.dispatch = dispatch  # the action router's on_stream_event: Pepper's say actions
        self.records: ConversationRecords = records or (
            MongoConversations(store.db) if getattr(store, "db", None) is not None else MemoryConversations())
        self.process = getattr(store, "process", None) or f"{socket.gethostname()}:{os.getpid()}"
        self.recogniser = Recogniser()
        self._local: collections.OrderedDict[str, Local] = collections.OrderedDict()
        self._lock = threading.Lock()
        self._stripes = [threading.Lock() for _ in range(64)]  # one conversation's turns here, one at a time
        self._turns = threading.BoundedSemaphore(settings.max_concurrent_turns)
        self._order_listeners: list[Callable[[dict[str, Any]], None]] = []
        self._stop = threading.Event()
        self._watcher: threading.Thread | None = None
        self._changed = threading.Condition()  # an order completed or a conversation finished here
        self._events: collections.deque[tuple[int, str, str, dict[str, Any]]] = collections.deque(maxlen=1000)
        self._seq = 0

    # ------------------------------------------------------------------ vocabulary and grammar

    def menu(self) -> Menu:
        """The drinks of the live ontology (follows every knowledge edit)."""
        k = self.knowledge
        return read_menu(k.text("ontology"), k.base, k.files["ontology"].endswith((".ttl", ".n3")))

    def grammar(self) -> Grammar:
        """The recogniser's grammar from the live dialogue rules and the menu."""
        return build(self.engine.current(self.settings.ruleset).files, self.menu())

    def add_order_listener(self, listener: Callable[[dict[str, Any]], None]) -> None:
        """``listener(order)`` for every order this process keeps (errors are logged)."""
        self._order_listeners.append(listener)

    # ------------------------------------------------------------------ turns

    def turn(self, conversation: str, *, text: str | None = None, audio: bytes | None = None,
             table: str | None = None, confidence: float | None = None) -> dict[str, Any]:
        """One turn: ``{"conversation", "heard", "intent", "slots", "actions", "state", "decision_id", ...}``."""
        self._check(conversation, text, audio, table)
        if not self._turns.acquire(blocking=False):
            raise DialogueBusy(f"{self.settings.max_concurrent_turns} turns are being processed "
                               "(dialogue.max_concurrent_turns): try again in a moment", 503)
        try:
            recognised = None
            if audio is not None:
                try:
                    samples, _seconds = read_wav(audio, self.settings.max_audio_s)
                except ValueError as exc:
                    raise DialogueRefused("audio", str(exc)) from None
                recognised = self.recogniser.recognise(samples, self.grammar())
                text, confidence = recognised.text, recognised.confidence
            answer = self._run_turn(conversation, table, text or "", confidence)
            if recognised is not None:
                answer["recognition"] = {"latency_ms": recognised.latency_ms, "duration_s": round(recognised.duration_s, 3)}
            return answer
        finally:
            self._turns.release()

    def _check(self, conversation: str, text: str | None, audio: bytes | None, table: str | None) -> None:
        if not isinstance(conversation, str) or len(conversation) > 100 or not ID_PATTERN.match(conversation):
            raise DialogueRefused("conversation", f"conversation {conversation!r}: 1-100 letters, digits, '_', '.', ':' or '-'")
        if table is not None and not ID_PATTERN.match(table):
            raise DialogueRefused("table", f"table {table!r}: 1-128 letters, digits, '_', '.', ':' or '-'")
        if (text is None) == (audio is None):
            raise DialogueRefused("text", "give either text or audio (base64 WAV), not both and not neither")
        if text is not None and len(text) > self.settings.max_text_chars:
            raise DialogueRefused("text", f"text: {len(text)} characters, at most {self.settings.max_text_chars}")

    def _run_turn(self, conversation: str, table: str | None, text: str, confidence: float | None) -> dict[str, Any]:
        self.start_watching()
        menu = self.menu()
        heard = hear(text, menu)
        done = self._change(conversation, lambda doc: heard.fact(conversation, doc["turn"] + 1), table=table,
                            spoken=True)
        if done is None:  # cannot happen: a spoken turn starts a conversation when none is going on
            raise DialogueBusy(f"conversation {conversation}: no turn taken, say it again", 503)
        utterance = _find(done.result.facts, "Utterance", done.fact["id"]) or {}
        context = {"conversation": conversation, "table": done.doc["table"], "heard": heard.text,
                   "turn": done.doc["turn"], "intent": utterance.get("intent"),
                   **({"confidence": confidence} if confidence is not None else {})}
        answer = self._conclude(done, context, menu)
        answer.update({"heard": heard.text, "intent": utterance.get("intent"), "turn": done.doc["turn"]})
        if confidence is not None:
            answer["confidence"] = confidence
        return answer

    # ------------------------------------------------------------------ one change, read-run-write

    def _change(self, conversation: str, make_fact: Callable[[dict[str, Any]], dict[str, Any]], *,
                table: str | None = None, spoken: bool, still: Callable[[dict[str, Any]], bool] | None = None,
                ) -> Turn | None:
        """Reads the conversation's record, runs ``make_fact(record)`` through its session and
        writes the outcome over the ``rev`` it read, again on the newer state when another turn
        got there first. A spoken turn starts a conversation when none is going on; a silence
        (``spoken`` False) changes only one going on for which ``still(record)`` holds. None:
        nothing to change."""
        with self._stripe(conversation):
            for attempt in range(WRITE_ATTEMPTS):
                # first as this process last wrote it (no read: the write fails if another wrote since)
                doc = (self._cached(conversation) if attempt == 0 else None) or self._read(conversation)
                expected = doc["rev"] if doc is not None else None
                fresh = doc is None or not doc["going_on"]
                if fresh:
                    if not spoken:
                        return None
                    if doc is not None and doc.get("order_kept") is False:
                        self._rescue_order(doc)  # its process died before keeping it: the new one replaces it
                    doc = self._fresh(conversation, table, doc)
                elif still is not None and not still(doc):
                    return None
                try:
                    done = self._run(doc, make_fact(doc), spoken)
                except StateUnfit as exc:
                    if fresh:
                        raise
                    self._end_unfit(doc, exc)  # and start anew on the next attempt
                    continue
                if self._write(done.doc, expected, None if fresh else done.changes):
                    self._keep_local(conversation, done)
                    return done
                self._drop_local(conversation)  # another process took a turn: run again on its state
        raise DialogueBusy(f"conversation {conversation} was changed by {WRITE_ATTEMPTS} other turns at once: "
                           "say it again", 503)

    def _stripe(self, conversation: str) -> threading.Lock:
        """The lock one conversation's changes in this process take (64 shared by all)."""
        return self._stripes[hash(conversation) % len(self._stripes)]

    def _end_unfit(self, doc: dict[str, Any], exc: Exception) -> None:
        """A conversation whose kept facts the live rules no longer accept (an owner changed
        the types): ended, so the turn starts a new one rather than failing for ever."""
        log.warning("conversation %s ended: its facts do not fit the live %s rules (%s)", doc["_id"],
                    self.settings.ruleset, exc)
        changes = {"rev": doc["rev"] + 1, "going_on": False, "state": "ended", "ended_at": time.time(),
                   "process": self.process}
        self._write({**doc, **changes}, doc["rev"], changes)

    def _cached(self, conversation: str) -> dict[str, Any] | None:
        with self._lock:
            local = self._local.get(conversation)
            return copy.deepcopy(local.doc) if local is not None and not local.session.closed else None

    def _read(self, conversation: str) -> dict[str, Any] | None:
        try:
            return self.records.load(conversation)
        except RecordsUnavailable as exc:
            raise DialogueBusy(str(exc), 503) from None

    def _write(self, doc: dict[str, Any], expected: int | None, changes: dict[str, Any] | None) -> bool:
        try:
            return self.records.save(doc, expected, changes)
        except RecordsUnavailable as exc:
            self._drop_local(doc["_id"])  # the session ran a turn that is not written
            raise DialogueBusy(str(exc), 503) from None

    def _fresh(self, conversation: str, table: str | None, before: dict[str, Any] | None) -> dict[str, Any]:
        """The record of a new conversation (not written yet): only its ``Conversation`` fact."""
        try:
            going = self.records.count_going_on()
        except RecordsUnavailable as exc:
            raise DialogueBusy(str(exc), 503) from None
        if going >= self.settings.max_conversations:
            raise DialogueBusy(f"{going} conversations are going on (dialogue.max_conversations): "
                               "finish one first", 429)
        self._drop_local(conversation)
        where = table or conversation
        now = time.time()
        return {"_id": conversation, "generation": uuid.uuid4().hex, "rev": (before or {}).get("rev", 0),
                "going_on": True, "table": where, "state": "ordering", "slots": {"drink": None, "cups": None},
                "turn": 0, "decisions": [], "last_decision_id": None, "started_at": now, "last_turn_at": now,
                "last_silence_at": now, "ended_at": None, "order": None, "order_kept": None,
                "process": self.process,
                "facts": [{"type": "Conversation", "id": conversation, "table": where, "state": "ordering",
                           "drink": "", "cups": 0}]}

    def _run(self, doc: dict[str, Any], fact: dict[str, Any], spoken: bool) -> Turn:
        """Pushes ``fact`` into the conversation's session (this process's, or one made from the
        record); the new record, not yet written."""
        session = self._session(doc)
        try:
            result = session.push([fact], return_facts=True)
            if _find(result.facts, str(fact["type"]), fact["id"]):
                session.retract(fact["id"])  # the turn is over: only the Conversation stays
        except Exception:
            self._drop_local(doc["_id"])  # a session a failed push left half-changed is not used again
            raise
        kept = [f for f in result.facts if not (f.get("id") == fact["id"] and _named(f, str(fact["type"])))]
        state_fact = _find(kept, "Conversation", doc["_id"]) or {}
        state = str(state_fact.get("state") or doc["state"])
        now = time.time()
        changes = {"rev": doc["rev"] + 1, "facts": kept, "state": state, "process": self.process,
                   "slots": {"drink": state_fact.get("drink") or None, "cups": state_fact.get("cups") or None}}
        if spoken:
            changes.update(turn=doc["turn"] + 1, last_turn_at=now)
        else:
            changes["last_silence_at"] = now
        order = next((a.get("params") or {} for a in result.actions if a.get("module") == "order"), None)
        if order is not None:  # written with the turn, kept in `orders` once written (see _conclude)
            changes.update(order={k: order.get(k) for k in ("table", "drink", "cups")}, order_kept=False, order_at=now)
        if state in FINISHED:
            changes.update(going_on=False, ended_at=now)
        return Turn({**doc, **changes}, changes, result, fact, session)

    def _session(self, doc: dict[str, Any]) -> Any:
        """The conversation's session at the record's ``rev``: the one this process kept, or a new
        one with the record's facts (after a turn elsewhere, a crash, or a restart)."""
        conversation = doc["_id"]
        with self._lock:
            local = self._local.get(conversation)
        if local is not None and local.rev == doc["rev"] and not local.session.closed:
            local.used_at = time.monotonic()
            return local.session
        self._drop_local(conversation)
        manager = self.engine.session_manager
        session_id = f"dialogue.{conversation}"
        leftover = manager.find(self.settings.ruleset, session_id)
        if leftover is not None:
            leftover.close()
        session = manager.open(self.settings.ruleset, session_id=session_id, kind="dialogue")
        try:
            if doc["facts"]:
                session.insert(doc["facts"])
        except EngineError as exc:
            session.close()
            raise StateUnfit(str(exc)) from exc
        except Exception:
            session.close()
            raise
        return session

    def _keep_local(self, conversation: str, done: Turn) -> None:
        if not done.doc["going_on"]:
            self._drop_local(conversation)
            return
        with self._lock:
            self._local[conversation] = Local(conversation, done.session, done.doc["rev"], done.doc)
            self._local.move_to_end(conversation)
            evicted = []
            while len(self._local) > self.settings.max_conversations:
                evicted.append(self._local.popitem(last=False)[1])
        for old in evicted:  # a session in a turn right now is closed as a leftover at its next turn
            if self._stripe(old.conversation).acquire(blocking=False):
                try:
                    old.session.close()
                finally:
                    self._stripe(old.conversation).release()

    def _session_of(self, conversation: str) -> Any:
        return self.engine.session_manager.find(self.settings.ruleset, f"dialogue.{conversation}")

    def _drop_local(self, conversation: str) -> None:
        with self._lock:
            local = self._local.pop(conversation, None)
        session = local.session if local is not None else self._session_of(conversation)
        if session is not None:
            try:
                session.close()
            except Exception:
                log.debug("closing the session of conversation %s failed", conversation, exc_info=True)

    # ------------------------------------------------------------------ after a change is written

    def _conclude(self, done: Turn, context: dict[str, Any], menu: Menu) -> dict[str, Any]:
        """What a written change did: the answer filled in, the decision, the order, Pepper."""
        doc, result = done.doc, done.result
        slots = doc["slots"]
        drink_label = slots["drink"] or ""
        fill = {"drink": drink_label, "cups": str(slots["cups"] or ""),
                "drinks": menu.plural_of(drink_label) if (slots["cups"] or 0) > 1 else drink_label}
        actions = [_filled(a, fill) for a in result.actions]
        result.actions = actions
        decision_id = self.engine.recorder.record(result, [done.fact], origin="dialogue", correlation_id=doc["_id"],
                                                  context={**context, "state": doc["state"]})
        doc["decisions"] = [*doc["decisions"], decision_id]
        doc["last_decision_id"] = decision_id
        self._note(doc, {"last_decision_id": decision_id}, decision_id)
        if "order" in done.changes and self._claim_order(doc, time.time() - ORPHAN_ORDER_S):
            self._keep_order(doc, menu)
        robot = [a for a in actions if a.get("module") in ROBOT_MODULES]
        if robot and self.dispatch is not None:
            self.dispatch({"kind": "actions", "actions": robot, "decision_id": decision_id,
                           "ruleset": self.settings.ruleset, "query": "dialogue"})
        answer = {"conversation": doc["_id"], "table": doc["table"], "slots": dict(slots), "actions": actions,
                  "state": doc["state"], "decision_id": decision_id,
                  "says": [a["params"].get("text") for a in actions if a.get("module") == "say"]}
        if not doc["going_on"]:
            self._announce(doc["_id"], doc["state"], answer)
        return answer

    def _note(self, doc: dict[str, Any], changes: dict[str, Any], decision: str | None = None) -> None:
        try:
            self.records.note(doc["_id"], doc["generation"], changes, decision)
        except RecordsUnavailable:
            log.warning("conversation %s: %s not noted (the Information State is away)", doc["_id"], changes)

    def _keep_order(self, doc: dict[str, Any], menu: Menu) -> dict[str, Any]:
        """The confirmed order kept in ``orders`` (under an id of its own: kept twice is kept
        once), marked kept on the conversation, and handed to listeners (the ROS topic)."""
        params = doc["order"]
        drink = str(params.get("drink") or "")
        individual = next((d.individual for d in menu.drinks if d.label == drink), None)
        cups = int(params.get("cups") or 0)
        order = {"conversation": doc["_id"], "table": str(params.get("table") or doc["table"]), "drink": drink,
                 "drinks": menu.plural_of(drink) if cups > 1 else drink, "individual": individual, "cups": cups,
                 "at": datetime.now(timezone.utc).isoformat(), "decision_ids": list(doc["decisions"])}
        if self.store is not None:
            self.store.record(ORDERS, {"_id": f"{doc['_id']}:{doc['generation']}", **order},
                              stored_type="printeps/Order", inserted_by="dialogue")
        self._note(doc, {"order": order, "order_kept": True})
        self._announce(doc["_id"], "order", order)
        for listener in list(self._order_listeners):
            try:
                listener(dict(order))
            except Exception:
                log.exception("order listener failed")
        return order

    def _announce(self, conversation: str, what: str, payload: dict[str, Any]) -> None:
        with self._changed:
            self._seq += 1
            self._events.append((self._seq, conversation, what, payload))
            self._changed.notify_all()

    # ------------------------------------------------------------------ the take_order workflow step

    def take_order(self, conversation: str, *, table: str | None = None, customer_says: list[str] | None = None,
                   opening: str | None = None, timeout_s: float = 120.0,
                   cancelled: threading.Event | None = None) -> dict[str, Any]:
        """Run the conversation until it completes an order; the order. Pepper opens with
        ``opening`` (e.g. "What would you like to drink?"); ``customer_says`` plays a simulated
        customer's sentences as text turns; without them, what real customers say (REST, ROS —
        on any gateway process) carries it. LookupError when it ends without an order or
        ``timeout_s`` passes."""
        with self._changed:
            start = self._seq
        since = time.time()
        if opening and self.dispatch is not None:
            self.dispatch({"kind": "actions", "query": "dialogue", "ruleset": self.settings.ruleset,
                           "actions": [{"module": "say", "params": {"robot": self.settings.robot, "text": opening}}]})
        for sentence in customer_says or []:
            if self._outcome(conversation, start, since) is not None:
                break
            self.turn(conversation, text=sentence, table=table)
        deadline = time.monotonic() + timeout_s
        while True:
            outcome = self._outcome(conversation, start, since)
            if outcome is not None:
                break
            left = deadline - time.monotonic()
            if left <= 0 or (cancelled is not None and cancelled.is_set()):
                raise LookupError(f"conversation {conversation}: no order within {timeout_s:g} s")
            with self._changed:
                self._changed.wait(min(left, 0.25))
        what, payload = outcome
        if what != "order":
            raise LookupError(f"conversation {conversation} {what} without an order")
        return payload

    def _outcome(self, conversation: str, after: int, since: float) -> tuple[str, dict[str, Any]] | None:
        """How the conversation ended since the step began: told here, or read from its record
        (a turn another process took)."""
        with self._changed:
            for seq, conv, what, payload in self._events:
                if seq > after and conv == conversation and what in ("order", "ended"):
                    return what, dict(payload)
        try:
            doc = self.records.load(conversation)
        except RecordsUnavailable:
            return None
        if doc is None:
            return None
        if doc.get("order_kept") and (doc.get("order_at") or 0) >= since:
            return "order", dict(doc["order"])
        if doc["going_on"] or (doc.get("ended_at") or 0) < since or doc.get("order_kept") is False:
            return None  # going on, ended before the step, or its order not kept yet
        return "ended", _summary(doc)

    # ------------------------------------------------------------------ silence

    def silence(self, conversation: str, seconds: int, *, quiet_since: float | None = None) -> dict[str, Any] | None:
        """Tell a conversation its customer said nothing for ``seconds``; the rules decide whether
        it ends (and what Pepper says). None when there is no such conversation going on (or,
        with ``quiet_since``, when it was not quiet since then after all: another process took a
        turn or told it first)."""
        def still(doc: dict[str, Any]) -> bool:
            return quiet_since is None or max(doc["last_turn_at"], doc["last_silence_at"]) <= quiet_since

        done = self._change(conversation, lambda doc: {"type": "Silence", "id": f"{conversation}#silence{doc['turn']}-{int(seconds)}",
                                                       "conversation": conversation, "seconds": int(seconds)},
                            spoken=False, still=still)
        if done is None:
            return None
        return self._conclude(done, {"conversation": conversation, "table": done.doc["table"],
                                     "silence_s": int(seconds)}, self.menu())

    def start_watching(self) -> None:
        """Looks for quiet conversations every ``watch_interval_s`` — every process does, so a
        conversation whose process is gone is still told of its silence."""
        if self._watcher is None or not self._watcher.is_alive():
            self._watcher = threading.Thread(target=self._watch, name="dialogue-silence", daemon=True)
            self._watcher.start()

    def _watch(self) -> None:
        while not self._stop.wait(self.settings.watch_interval_s):
            try:
                self.check_silences()
            except RecordsUnavailable as exc:
                log.debug("silences not checked: %s", exc)
            except Exception:
                log.exception("checking the conversations' silences failed")

    def check_silences(self, now: float | None = None) -> list[dict[str, Any]]:
        """Tell every conversation silent for ``silence_check_s`` (since its last turn or last
        check) so, close those idle for ``max_idle_s``, and keep the orders a dead process
        confirmed but did not keep; returns what the told ones answered. ``now``: epoch seconds."""
        now = time.time() if now is None else now
        self._close_stale(now)
        self._keep_orphaned_orders(now)
        self._forget_idle_sessions()
        out = []
        for doc in self.records.quiet(now - self.settings.silence_check_s):
            try:
                answer = self.silence(doc["_id"], int(now - doc["last_turn_at"]),
                                      quiet_since=now - self.settings.silence_check_s)
            except Exception:  # one broken conversation must not stop the others' time-outs
                log.exception("telling conversation %s of its silence failed", doc["_id"])
                continue
            if answer is not None:
                out.append(answer)
        return out

    def _close_stale(self, now: float) -> None:
        """Conversations idle ``max_idle_s``: ended whatever the rules said, so they cannot pile up."""
        for doc in self.records.stale(now - self.settings.max_idle_s):
            log.info("conversation %s idle for %.0f s: closed", doc["_id"], now - doc["last_turn_at"])
            changes = {"rev": doc["rev"] + 1, "going_on": False, "state": "ended", "ended_at": time.time(),
                       "process": self.process}
            closed = {**doc, **changes}
            with self._stripe(doc["_id"]):
                if not self.records.save(closed, doc["rev"], changes):
                    continue  # a turn came after all
                self._drop_local(doc["_id"])
            self._announce(doc["_id"], "ended", _summary(closed))

    def _keep_orphaned_orders(self, now: float) -> None:
        for doc in self.records.unkept_orders(now - ORPHAN_ORDER_S):
            self._rescue_order(doc, now)

    def _rescue_order(self, doc: dict[str, Any], now: float | None = None) -> None:
        """Keeps an order its process wrote but did not keep (it died in between), unless
        another process claims it first."""
        if self._claim_order(doc, (now or time.time()) - ORPHAN_ORDER_S):
            log.warning("conversation %s: the order confirmed by process %s was not kept; kept now",
                        doc["_id"], doc.get("process"))
            self._keep_order(doc, self.menu())

    def _claim_order(self, doc: dict[str, Any], stale_before: float) -> bool:
        try:
            return self.records.claim_order(doc["_id"], doc["generation"], stale_before)
        except RecordsUnavailable:
            log.warning("conversation %s: the order is kept later (the Information State is away)", doc["_id"])
            return False

    def _forget_idle_sessions(self) -> None:
        """Sessions of conversations not continued here for a while (they may go on elsewhere)."""
        limit = time.monotonic() - self.settings.silence_check_s
        with self._lock:
            idle = [c for c, local in self._local.items() if local.used_at < limit]
        for conversation in idle:
            with self._stripe(conversation):  # not while a turn uses it
                with self._lock:
                    local = self._local.get(conversation)
                if local is not None and local.used_at < limit:
                    self._drop_local(conversation)

    # ------------------------------------------------------------------ reading

    def conversations(self) -> list[dict[str, Any]]:
        """The conversations going on, on every process of the Information State."""
        now = time.time()
        return [{"conversation": d["_id"], "table": d["table"], "state": d["state"], "turns": d["turn"],
                 "idle_s": round(now - d["last_turn_at"], 1), "process": d.get("process")}
                for d in self.records.going_on(self.settings.max_conversations)]

    @property
    def finished(self) -> dict[str, dict[str, Any]]:
        """The last state of recently finished conversations, by conversation."""
        return {d["_id"]: _summary(d) for d in self.records.finished(self.settings.max_conversations)}

    def close(self) -> None:
        self._stop.set()
        with self._lock:
            conversations = list(self._local)
        for conversation in conversations:
            self._drop_local(conversation)


def _summary(doc: dict[str, Any]) -> dict[str, Any]:
    return {"conversation": doc["_id"], "table": doc["table"], "slots": doc.get("slots") or {},
            "state": doc["state"], "decision_id": doc.get("last_decision_id")}


def _named(fact: dict[str, Any], type_name: str) -> bool:
    return str(fact.get("type", "")).rsplit(".", 1)[-1] == type_name


def _find(facts: list[dict[str, Any]], type_name: str, fact_id: str) -> dict[str, Any] | None:
    return next((f for f in facts if str(f.get("type", "")).rsplit(".", 1)[-1] == type_name and f.get("id") == fact_id), None)


def _filled(action: dict[str, Any], values: dict[str, str]) -> dict[str, Any]:
    """A ``say`` action with ``{drink}``, ``{drinks}``, ``{cups}`` replaced; others as they are."""
    params = action.get("params") or {}
    text = params.get("text")
    if action.get("module") != "say" or not isinstance(text, str) or "{" not in text:
        return action
    for key, value in values.items():
        text = text.replace("{" + key + "}", value)
    return {**action, "params": {**params, "text": text}}
