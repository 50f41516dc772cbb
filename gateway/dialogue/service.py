"""The dialogue service: one turn of a conversation at a table, in and out.

Why a service of its own (built once, in :func:`gateway.app.build_gateway`): a conversation is
state kept across turns — a stateful session of the dialogue rule set per conversation (one per
table), whose ``Conversation`` fact holds the order's slots and the state — and a turn touches
the recogniser, the rules, the decision record, the robots and the Information State's ``orders``.
The REST route, the ROS ``Utterance`` topic and the ``take_order`` workflow all come here.

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
import logging
import threading
import time
from dataclasses import dataclass, field
from datetime import datetime, timezone
from typing import Any, Callable

from gateway.config import DialogueSettings
from gateway.dialogue.grammar import Grammar, build
from gateway.dialogue.menu import Menu, read_menu
from gateway.dialogue.speech import Recogniser, read_wav
from gateway.dialogue.words import hear
from gateway.engine.sessions import ID_PATTERN

log = logging.getLogger(__name__)

ORDERS = "orders"
FINISHED = ("ordered", "ended")  # a conversation in these states takes no more turns: the next one starts anew
ROBOT_MODULES = ("say", "move", "gesture")


class DialogueRefused(ValueError):
    """A turn refused as asked (bad conversation id, neither or both of text and audio, bad audio):
    ``field`` names what is wrong; nothing changed."""

    def __init__(self, field_name: str, message: str) -> None:
        super().__init__(message)
        self.field, self.message = field_name, message


class DialogueBusy(RuntimeError):
    """Too many turns at once (``status`` 503) or conversations going on (429): try again later."""

    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


@dataclass
class Conversation:
    """One conversation going on: its session and what it has decided so far."""

    id: str
    table: str
    session: Any
    turn: int = 0
    state: str = "ordering"
    decisions: list[str] = field(default_factory=list)
    last_turn_at: float = field(default_factory=time.monotonic)
    last_silence_at: float = 0.0
    lock: threading.Lock = field(default_factory=threading.Lock)


class DialogueService:
    """Turns of conversations (see the module docstring). Thread-safe."""

    def __init__(self, engine: Any, knowledge: Any, settings: DialogueSettings, *, store: Any = None,
                 dispatch: Callable[[dict[str, Any]], None] | None = None) -> None:
        self.engine = engine
        self.knowledge = knowledge
        self.settings = settings
        self.store = store
        self.dispatch = dispatch  # the action router's on_stream_event: Pepper's say actions
        self.recogniser = Recogniser()
        self._conversations: dict[str, Conversation] = {}
        self._lock = threading.Lock()
        self._turns = threading.BoundedSemaphore(settings.max_concurrent_turns)
        self._order_listeners: list[Callable[[dict[str, Any]], None]] = []
        self._stop = threading.Event()
        self._watcher: threading.Thread | None = None
        self.finished: dict[str, dict[str, Any]] = {}  # the last state of recently finished conversations
        self._changed = threading.Condition()  # an order completed or a conversation finished
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
        """``listener(order)`` for every completed order (errors are logged)."""
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
            conv = self._conversation(conversation, table)
            with conv.lock:
                answer = self._run_turn(conv, text or "", confidence)
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

    def _conversation(self, conversation: str, table: str | None) -> Conversation:
        with self._lock:
            conv = self._conversations.get(conversation)
            if conv is not None and not conv.session.closed:
                return conv
            if len(self._conversations) >= self.settings.max_conversations:
                raise DialogueBusy(f"{len(self._conversations)} conversations are going on "
                                   "(dialogue.max_conversations): finish one first", 429)
            session = self.engine.session_manager.open(self.settings.ruleset, session_id=f"dialogue.{conversation}",
                                                       kind="dialogue")
            where = table or conversation
            session.insert([{"type": "Conversation", "id": conversation, "table": where, "state": "ordering",
                             "drink": "", "cups": 0}])
            conv = Conversation(conversation, where, session)
            self._conversations[conversation] = conv
            self.finished.pop(conversation, None)
            self._ensure_watcher()
            return conv

    def _run_turn(self, conv: Conversation, text: str, confidence: float | None) -> dict[str, Any]:
        menu = self.menu()
        heard = hear(text, menu)
        conv.turn += 1
        conv.last_turn_at = time.monotonic()
        fact = heard.fact(conv.id, conv.turn)
        result = conv.session.push([fact], return_facts=True)
        utterance = _find(result.facts, "Utterance", fact["id"]) or {}
        if utterance:
            conv.session.retract(fact["id"])  # the turn is over: only the Conversation stays
        context = {"conversation": conv.id, "table": conv.table, "heard": heard.text, "turn": conv.turn,
                   "intent": utterance.get("intent"), **({"confidence": confidence} if confidence is not None else {})}
        answer = self._conclude(conv, result, [fact], context, menu)
        answer.update({"heard": heard.text, "intent": utterance.get("intent"), "turn": conv.turn})
        if confidence is not None:
            answer["confidence"] = confidence
        return answer

    def _conclude(self, conv: Conversation, result: Any, facts: list[dict[str, Any]], context: dict[str, Any],
                  menu: Menu) -> dict[str, Any]:
        """What a fire on the conversation did: the answer filled in, the decision, the order, Pepper."""
        state_fact = _find(result.facts, "Conversation", conv.id) or {}
        conv.state = str(state_fact.get("state") or conv.state)
        slots = {"drink": state_fact.get("drink") or None, "cups": state_fact.get("cups") or None}
        drink_label = slots["drink"] or ""
        fill = {"drink": drink_label, "cups": str(slots["cups"] or ""),
                "drinks": menu.plural_of(drink_label) if (slots["cups"] or 0) > 1 else drink_label}
        actions = [_filled(a, fill) for a in result.actions]
        result.actions = actions
        decision_id = self.engine.record_decision(result, facts, origin="dialogue", correlation_id=conv.id,
                                                  context={**context, "state": conv.state})
        conv.decisions.append(decision_id)
        for action in actions:
            if action.get("module") == "order":
                self._order(conv, action.get("params") or {}, menu)
        robot = [a for a in actions if a.get("module") in ROBOT_MODULES]
        if robot and self.dispatch is not None:
            self.dispatch({"kind": "actions", "actions": robot, "decision_id": decision_id,
                           "ruleset": self.settings.ruleset, "query": "dialogue"})
        answer = {"conversation": conv.id, "table": conv.table, "slots": slots, "actions": actions,
                  "state": conv.state, "decision_id": decision_id,
                  "says": [a["params"].get("text") for a in actions if a.get("module") == "say"]}
        if conv.state in FINISHED:
            self._finish(conv, answer)
        return answer

    def _order(self, conv: Conversation, params: dict[str, Any], menu: Menu) -> None:
        drink = str(params.get("drink") or "")
        individual = next((d.individual for d in menu.drinks if d.label == drink), None)
        cups = int(params.get("cups") or 0)
        order = {"conversation": conv.id, "table": str(params.get("table") or conv.table), "drink": drink,
                 "drinks": menu.plural_of(drink) if cups > 1 else drink, "individual": individual, "cups": cups,
                 "at": datetime.now(timezone.utc).isoformat(), "decision_ids": list(conv.decisions)}
        if self.store is not None:
            self.store.record(ORDERS, order, stored_type="printeps/Order", inserted_by="dialogue")
        self._announce(conv.id, "order", order)
        for listener in list(self._order_listeners):
            try:
                listener(dict(order))
            except Exception:
                log.exception("order listener failed")

    def _finish(self, conv: Conversation, answer: dict[str, Any]) -> None:
        with self._lock:
            if self._conversations.get(conv.id) is conv:
                del self._conversations[conv.id]
            self.finished[conv.id] = {k: answer[k] for k in ("conversation", "table", "slots", "state", "decision_id")}
            while len(self.finished) > self.settings.max_conversations:
                self.finished.pop(next(iter(self.finished)))
        conv.session.close()
        self._announce(conv.id, conv.state, answer)

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
        customer's sentences as text turns; without them, what real customers say (REST, ROS)
        carries it. LookupError when it ends without an order or ``timeout_s`` passes."""
        with self._changed:
            start = self._seq
        if opening and self.dispatch is not None:
            self.dispatch({"kind": "actions", "query": "dialogue", "ruleset": self.settings.ruleset,
                           "actions": [{"module": "say", "params": {"robot": self.settings.robot, "text": opening}}]})
        for sentence in customer_says or []:
            if self._outcome(conversation, start) is not None:
                break
            self.turn(conversation, text=sentence, table=table)
        deadline = time.monotonic() + timeout_s
        with self._changed:
            while True:
                outcome = self._outcome(conversation, start)
                if outcome is not None:
                    break
                left = deadline - time.monotonic()
                if left <= 0 or (cancelled is not None and cancelled.is_set()):
                    raise LookupError(f"conversation {conversation}: no order within {timeout_s:g} s")
                self._changed.wait(min(left, 0.25))
        what, payload = outcome
        if what != "order":
            raise LookupError(f"conversation {conversation} {what} without an order")
        return payload

    def _outcome(self, conversation: str, after: int) -> tuple[str, dict[str, Any]] | None:
        with self._changed:
            for seq, conv, what, payload in self._events:
                if seq > after and conv == conversation and what in ("order", "ended"):
                    return what, dict(payload)
        return None

    # ------------------------------------------------------------------ silence

    def silence(self, conversation: str, seconds: int) -> dict[str, Any] | None:
        """Tell a conversation its customer said nothing for ``seconds``; the rules decide whether
        it ends (and what Pepper says). None when there is no such conversation going on."""
        with self._lock:
            conv = self._conversations.get(conversation)
        if conv is None:
            return None
        with conv.lock:
            if conv.session.closed:
                return None
            conv.last_silence_at = time.monotonic()
            fact = {"type": "Silence", "id": f"{conv.id}#silence{conv.turn}-{int(seconds)}", "conversation": conv.id,
                    "seconds": int(seconds)}
            result = conv.session.push([fact], return_facts=True)
            if _find(result.facts, "Silence", fact["id"]):
                conv.session.retract(fact["id"])
            return self._conclude(conv, result, [fact], {"conversation": conv.id, "table": conv.table,
                                                         "silence_s": int(seconds)}, self.menu())

    def _ensure_watcher(self) -> None:
        if self._watcher is None or not self._watcher.is_alive():
            self._watcher = threading.Thread(target=self._watch, name="dialogue-silence", daemon=True)
            self._watcher.start()

    def _watch(self) -> None:
        while not self._stop.wait(self.settings.watch_interval_s):
            self.check_silences()

    def check_silences(self, now: float | None = None) -> list[dict[str, Any]]:
        """Tell every conversation silent for ``silence_check_s`` (since its last turn or last
        check) so, and close those idle for ``max_idle_s``; returns what the told ones answered."""
        now = time.monotonic() if now is None else now
        limit = self.settings.silence_check_s
        with self._lock:
            quiet = [c for c in self._conversations.values() if now - max(c.last_turn_at, c.last_silence_at) >= limit]
            stale = [c for c in self._conversations.values() if now - c.last_turn_at >= self.settings.max_idle_s]
        for conv in stale:  # the rules kept it going: closed anyway, so conversations cannot pile up
            log.info("conversation %s idle for %.0f s: closed", conv.id, now - conv.last_turn_at)
            with conv.lock:
                self._finish(conv, {"conversation": conv.id, "table": conv.table, "slots": {}, "state": "ended",
                                    "decision_id": conv.decisions[-1] if conv.decisions else None})
        quiet = [c for c in quiet if c not in stale]
        out = []
        for conv in quiet:
            try:
                answer = self.silence(conv.id, int(now - conv.last_turn_at))
            except Exception:  # one broken conversation must not stop the others' time-outs
                log.exception("telling conversation %s of its silence failed", conv.id)
                continue
            if answer is not None:
                out.append(answer)
        return out

    # ------------------------------------------------------------------ reading

    def conversations(self) -> list[dict[str, Any]]:
        with self._lock:
            going = [{"conversation": c.id, "table": c.table, "state": c.state, "turns": c.turn,
                      "idle_s": round(time.monotonic() - c.last_turn_at, 1)} for c in self._conversations.values()]
        return going

    def close(self) -> None:
        self._stop.set()
        with self._lock:
            convs = list(self._conversations.values())
            self._conversations.clear()
        for conv in convs:
            try:
                conv.session.close()
            except Exception:
                log.debug("closing conversation %s failed", conv.id, exc_info=True)


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
