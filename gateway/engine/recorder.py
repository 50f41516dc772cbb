"""The one decision recorder: every decision, from every origin, is built and journalled here.

A decision is one firing of a rule set on facts, whatever asked for it: a stateless fire (REST,
the ROS service, a workflow step, the CLI), a fire in a stateful session (REST session routes, a
KIE batch), a stream binding's window (stateless or in its session), a dialogue turn. Callers say
what they know (the outcome, the facts they sent, the ``origin``, their ``correlation_id`` and a
``context``); the recorder gives the decision its id, builds the one document replay, explain,
traces, durable sessions and the workbench read, journals it to ``decisions`` in the Information
State (:mod:`gateway.store.decisions` reads it back) and tells the engine's listeners (the live
feed, metrics) with that same document.

Why one place: the record's format is a contract of the Information State. When each route built
its own record, a new origin or field had to be added in four places and they drifted (a KIE
batch and a REST session fire count their fires differently; both are kept as they were).
``tests/meta/test_one_recorder.py`` checks that no other module writes ``decisions`` or builds a
decision, and ``tests/sync/test_decision_format.py`` pins each origin's stored document.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

from bson import ObjectId

from gateway.engine.results import FireResult
from gateway.store.decisions import DECISIONS, now_text
from gateway.store.store import process_name

if TYPE_CHECKING:  # pragma: no cover
    from gateway.engine.session import BatchAnswer
    from gateway.store.decisions import DecisionRecord

STORED_TYPE = "printeps/Decision"
Notify = Callable[[str, dict[str, Any]], None]


def new_decision_id() -> str:
    """A decision's id: an ObjectId's text (time-ordered, unique across processes), so the
    Information State can use it as the document ``_id`` and page through decisions by it."""
    return str(ObjectId())


class DecisionRecorder:
    """Builds each decision's document and journals it; one per engine (``engine.recorder``).

    ``notify`` tells the engine's listeners (``"fire"``, the document); ``heard()`` says whether
    any listens to decisions: with nothing journalled and nobody listening (an engine of its own,
    or ``store.record_fires`` off without a live feed), a decision gets its id and no document is
    built (the document, its time stamp and the notification were most of the recording's cost:
    about 15 of 20 us per decision). ``enabled`` is
    ``store.record_fires`` (off: nothing is journalled, listeners still hear); ``max_facts`` is
    ``store.decision_facts_max`` (the facts kept per decision; their count is always kept)."""

    def __init__(self, notify: Notify, *, enabled: bool = True, max_facts: int = 1000,
                 heard: Callable[[], bool] = lambda: True) -> None:
        self._notify = notify
        self._heard = heard
        self.enabled = enabled
        self.max_facts = max_facts
        self.process = process_name()
        self._record: DecisionRecord | None = None

    def journal_to(self, record: DecisionRecord) -> None:
        """Journal decisions to ``record``'s Information State (and keep its recent ones in memory,
        so one not shipped yet is found anyway)."""
        self._record = record

    # ---- the origins ---------------------------------------------------------------------------
    def record(self, result: FireResult, facts: list[dict[str, Any]], *, origin: str,
               correlation_id: str | None = None, context: dict[str, Any] | None = None) -> str:
        """Record ``result`` (a fire on ``facts``) as a decision; sets and returns its ``decision_id``.

        The one entry of every origin: a stateless fire (``engine.fire``, the REST fire route),
        a stream binding's window, a dialogue turn, and the session helpers below."""
        decision_id = new_decision_id()
        result.decision_id = decision_id
        journal = self._record if self.enabled else None
        if journal is None and not self._heard():
            return decision_id  # nobody keeps or hears the document: not built
        doc = self.document(decision_id, result, facts, origin, correlation_id, context)
        if journal is not None:
            journal.remember(doc)
            # check_keys=False: built here from checked parts (facts the engine accepted), on the fire path
            journal.store.record(DECISIONS, doc, stored_type=STORED_TYPE, inserted_by=self.process, check_keys=False)
        self._notify("fire", doc)  # after the journal: a decision shown live can be opened
        return decision_id

    def session_fire(self, ruleset: str, commands: list[dict[str, Any]], answer: BatchAnswer, *, duration_ms: float,
                     origin: str, correlation_id: str | None = None,
                     context: dict[str, Any] | None = None) -> FireResult:
        """A session batch that ends with a fire (the REST session routes): the decision is that
        last fire, on the facts the batch inserted. Returns it as a FireResult (with its id)."""
        fire = answer.results[-1]["fire"]
        result = FireResult(ruleset, answer.version, fire["actions"], fire["fired"], [], int(fire["fireCount"]),
                            duration_ms)
        inserted = [f for c in commands if c["op"] == "insert" for f in c["facts"]]
        self.record(result, inserted, origin=origin, correlation_id=correlation_id, context=context)
        return result

    def batch(self, ruleset: str, answer: BatchAnswer, facts: list[dict[str, Any]], *, origin: str,
              correlation_id: str | None = None, context: dict[str, Any] | None = None) -> str | None:
        """A KIE batch: all its fires together are one decision (their rules and actions, in order)
        on the facts it inserted; None when the batch fired nothing (no decision)."""
        if not answer.fires:
            return None
        fired = answer.fired()
        result = FireResult(ruleset, answer.version, answer.actions(), fired, fire_count=len(fired),
                            duration_ms=answer.duration_ms)
        return self.record(result, facts, origin=origin, correlation_id=correlation_id, context=context)

    # ---- the document --------------------------------------------------------------------------
    def document(self, decision_id: str, result: FireResult, facts: list[dict[str, Any]], origin: str,
                 correlation_id: str | None, context: dict[str, Any] | None) -> dict[str, Any]:
        """The stored decision (its fields and their order are a contract; see the module docstring)."""
        facts = facts or []
        kept = facts if len(facts) <= self.max_facts else facts[: self.max_facts]
        return {
            "_id": decision_id,
            "decision_id": decision_id,
            "origin": origin or "api",
            "correlation_id": correlation_id,
            "ruleset": result.ruleset,
            "version": result.version,
            "facts": kept,
            "facts_count": len(facts),
            "fired": [f["rule"] for f in result.fired],
            "actions": list(result.actions or []),
            "fire_count": result.fire_count,
            "duration_ms": result.duration_ms,
            "context": context or {},
            "at": now_text(),
            "process": self.process,
        }
