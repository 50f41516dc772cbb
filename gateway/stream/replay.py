"""Stream replay: re-run recorded sensor input through a candidate query, mapping or rule set.

Why: a threshold in a continuous query (the entry distance) or a mapping decides which guests a
robot greets long before any rule fires; a rule-set replay (:mod:`gateway.engine.replay`) cannot
show what such a change does. The Information State holds what the ROS ingress took in — every
message (``sensor_messages``) and the RDF it became (``rdf_events``), stamped with event time — so a
period of it can be pushed again through the gateway's continuous queries and rule bindings, once
as they are (the *baseline*) and once with the candidate, and the two compared window by window.

Both runs are scratch :class:`~gateway.stream.engine.StreamEngine`\\ s with the live engine's
settings, ontology, static graphs and context providers, and every query the gateway serves (as
stored), the candidate's replacing or adding some. Time comes from the recorded stamps only (the
stream engine never reads the wall clock): a pseudo clock, with the ROS side's heartbeat once a
second of event time, and the last windows closed at the end of the period. Their bindings fire on
the pushing thread, in window order (no skipped or late window), on rule sets compiled for the run,
whose ``actions`` only record. Nothing is recorded, nothing reaches a robot, nothing live changes.

Compared, per query and window: the *detection* (the window's rows, when it had any) and the
*decision* (the rules fired and the actions asked, as a multiset). A stateful binding's decisions
depend on its session's history, not on a window: such a query is replayed for its detections and
its binding is reported as not replayable.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import orjson
import pyoxigraph
from pymongo.errors import PyMongoError

from gateway.engine.errors import EngineError
from gateway.engine.replay import same_outcome
from gateway.rdf.mapping import Mapper, MappingError, NodeMap
from gateway.store.store import RDF_EVENTS, SENSOR_MESSAGES, StoreUnavailable
from gateway.stream.engine import StreamEngine, StreamError
from gateway.stream.lexer import QueryParseError
from gateway.stream.rules import BindingError, RuleBinding

DEFAULT_LIMIT = 10_000  # recorded messages
MAX_LIMIT = 100_000
DEFAULT_MAX_CHANGES = 100
MAX_LISTED = 100  # errors and messages that could not be replayed, listed (all are counted)
MAX_KEPT = 200_000  # windows with rows or a decision kept per run (a bound on the replay's memory)
HEARTBEAT_MS = 1000  # the ROS side's heartbeat (ros.heartbeats): once a second
PROGRESS_EVERY = 200

Progress = Callable[[int, int, str], None]


class CandidateRefused(EngineError):
    """A stream replay's candidate (or selection) that cannot run: says which field and where (422)."""

    kind = "invalid"

    def __init__(self, message: str, field_name: str, **where: Any) -> None:
        super().__init__(message)
        self.field = field_name
        self.where = {k: v for k, v in where.items() if v is not None}

    def to_dict(self) -> dict[str, Any]:
        return {"error": str(self), "kind": self.kind, "field": self.field, **self.where,
                "errors": [{"field": self.field, "message": str(self), **self.where}]}


@dataclass(frozen=True)
class QueryCandidate:
    """A query as the candidate registers it (replacing the served one of that name, or added)."""

    text: str
    params: list[Any] | None = None
    binding: RuleBinding | None = None
    report: str | None = None
    keep_binding: bool = False  # no "rules" given: keep the served query's binding
    where: str = ""  # where the request gave it ("queries[0]"), for its errors


@dataclass(frozen=True)
class StreamReplayParams:
    """What a stream replay asks: the period of recorded input and the candidate."""

    since_ms: int | None = None
    until_ms: int | None = None
    streams: tuple[str, ...] | None = None
    limit: int = DEFAULT_LIMIT
    max_changes: int = DEFAULT_MAX_CHANGES
    queries: dict[str, QueryCandidate] = field(default_factory=dict)
    rulesets: dict[str, dict[str, Any]] = field(default_factory=dict)  # name -> {"files"} | {"version"}
    mappings: dict[str, NodeMap] = field(default_factory=dict)
    role: str | None = None


def check_limit(limit: int) -> None:
    """``limit`` is a number of messages a stream replay accepts, else CandidateRefused naming it."""
    if not 1 <= limit <= MAX_LIMIT:
        raise CandidateRefused(f"limit {limit}: a stream replay takes 1 to {MAX_LIMIT} recorded messages", "limit")


def epoch_ms(moment: datetime | None) -> int | None:
    return None if moment is None else int(moment.timestamp() * 1000)


# --------------------------------------------------------------------------- the recorded input


@dataclass
class Message:
    """One recorded message as both runs push it: on ``stream`` at ``ts``; ``before``/``after``
    are its triples for each run (the same, unless the candidate maps it differently)."""

    stream: str
    ts: int
    before: list[Any] | None
    after: list[Any] | None
    source: str = ""
    error: str = ""  # why it could not be made into triples (for one run or both)


def parse_recorded(triples: list[list[str]]) -> list[Any]:
    """The triples of an ``rdf_events`` document (N-Triples terms as text) as pyoxigraph terms."""
    if not triples:
        return []
    text = "".join(f"{s} {p} {o} .\n" for s, p, o in triples)
    return [(q.subject, q.predicate, q.object) for q in pyoxigraph.parse(text, format=pyoxigraph.RdfFormat.N_TRIPLES)]


def _selection(params: StreamReplayParams, stream_field: str, streams: Iterable[str] | None) -> dict[str, Any]:
    spec: dict[str, Any] = {"stamp_ms": {"$exists": True}}
    if params.since_ms is not None or params.until_ms is not None:
        spec["stamp_ms"] = {k: v for k, v in (("$gte", params.since_ms), ("$lt", params.until_ms)) if v is not None}
    if streams is not None:
        spec[stream_field] = {"$in": list(streams)}
    return spec


class RecordedInput:
    """The recorded messages of a period, oldest first (in the order the gateway took them in)."""

    def __init__(self, db: Any, params: StreamReplayParams, subscriptions: list[Any], live_mapper: Mapper,
                 candidate_mapper: Mapper | None) -> None:
        self.db = db
        self.params = params
        self.subs = {s.topic: s for s in subscriptions if params.streams is None or s.stream in params.streams}
        self.live_mapper = live_mapper
        self.candidate_mapper = candidate_mapper

    @property
    def source(self) -> str:
        """Raw messages when the candidate maps them anew, else the RDF the gateway made of them."""
        return SENSOR_MESSAGES if self.candidate_mapper is not None else RDF_EVENTS

    def _spec(self) -> dict[str, Any]:
        if self.source == RDF_EVENTS:
            return _selection(self.params, "stream", self.params.streams)
        spec = _selection(self.params, "source", self.subs)
        spec["error"] = {"$exists": False}
        return spec

    def count(self) -> int:
        try:
            return self.db[self.source].count_documents(self._spec())
        except PyMongoError as exc:
            raise StoreUnavailable(f"Information State unreachable: {type(exc).__name__}: {exc}") from exc

    def messages(self) -> Iterator[Message]:
        try:
            cursor = self.db[self.source].find(self._spec()).sort("_id", 1).limit(self.params.limit)
            for doc in cursor:
                yield self._rdf(doc) if self.source == RDF_EVENTS else self._mapped(doc)
        except PyMongoError as exc:
            raise StoreUnavailable(f"Information State unreachable: {type(exc).__name__}: {exc}") from exc

    @staticmethod
    def _rdf(doc: dict[str, Any]) -> Message:
        ts, stream = int(doc["stamp_ms"]), str(doc.get("stream"))
        try:
            triples = parse_recorded(doc.get("triples") or [])
        except (SyntaxError, ValueError, TypeError) as exc:
            return Message(stream, ts, None, None, str(doc.get("source", "")), f"recorded triples do not parse: {exc}")
        return Message(stream, ts, triples, triples, str(doc.get("source", "")))

    def _mapped(self, doc: dict[str, Any]) -> Message:
        sub = self.subs[doc["source"]]
        ts = int(doc["stamp_ms"])
        message = doc.get("message") or {}
        body = message.get(sub.select) if sub.select else message
        name = sub.mapping if isinstance(sub.mapping, str) else f"topic:{sub.topic}"
        out = Message(sub.stream, ts, None, None, sub.topic)
        errors = []
        for side, mapper in (("before", self.live_mapper), ("after", self.candidate_mapper)):
            try:
                setattr(out, side, mapper.map(body, ts, name))  # type: ignore[union-attr]
            except MappingError as exc:
                errors.append(f"{side}: {exc.where}: {exc.message}")
        out.error = "; ".join(errors)
        return out


# --------------------------------------------------------------------------- the rules of a run


class ReplayFire:
    """A fire's outcome as a stream binding publishes it (``to_dict``), never a decision."""

    def __init__(self, ruleset: str, version: Any, fired: list[str], actions: list[Any]) -> None:
        self.ruleset, self.version, self.fired, self.actions = ruleset, version, fired, actions

    def to_dict(self) -> dict[str, Any]:
        return {"ruleset": self.ruleset, "version": self.version, "fired": self.fired, "actions": self.actions,
                "decision_id": None}


class NoDecisions:
    """The recorder of a replay's rules: a replayed fire is never a decision (nothing is recorded)."""

    def record(self, result: Any, facts: list[dict[str, Any]], **_what: Any) -> None:
        return None


class ReplayRules:
    """What a scratch stream engine asks of the rules engine, answered by rule sets compiled for
    the run: their types, and fires that only record what the then-parts ask (never a decision)."""

    def __init__(self, engine: Any, compiled: dict[str, tuple[Any, Any]]) -> None:
        self._compiled = compiled  # name -> (label, CompiledRuleSet)
        self._fires = {name: engine.replay_fire(c) for name, (_label, c) in compiled.items()}
        self.recorder = NoDecisions()

    def declared_types(self, name: str) -> dict[str, dict[str, str]]:
        if name not in self._compiled:
            raise BindingError(f"unknown rule set {name!r}")
        return self._compiled[name][1].types

    def fire(self, name: str, facts: list[dict[str, Any]], *_args: Any, **_kwargs: Any) -> ReplayFire:
        if name not in self._fires:
            raise BindingError(f"rule set {name!r} is not served")
        fired, actions = self._fires[name](facts)
        return ReplayFire(name, self._compiled[name][0], fired, actions)

    def open_session(self, name: str, *_args: Any, **_kwargs: Any) -> Any:
        raise BindingError(f"a stateful binding of {name!r} is not replayed (its decisions depend on its session)")


def compile_rulesets(engine: Any, names: set[str], candidates: dict[str, dict[str, Any]], role: str | None,
                     progress: Progress) -> tuple[dict[str, tuple[Any, Any]], dict[str, tuple[Any, Any]]]:
    """The rule sets of both runs, ``name -> (label, compiled)``: the live versions (baseline;
    the label is the version), and the same with the candidate's in their place (a draft, labelled
    by its hash, or a stored version). A rule set that is not served is left out of the baseline
    (a binding to it then says so when it is registered)."""
    baseline: dict[str, tuple[Any, Any]] = {}
    for name in sorted(names - set(candidates)):
        try:
            version = engine.current(name).info.version
        except EngineError:
            continue
        baseline[name] = (version, engine.replay_candidate(name, version=version, role=role)[1])
    candidate = dict(baseline)
    for name in sorted(candidates):
        spec = candidates[name]
        try:
            version = engine.current(name).info.version
            baseline[name] = (version, engine.replay_candidate(name, version=version, role=role)[1])
        except EngineError:
            pass  # a new rule set: nothing fires it before
        label, compiled = engine.replay_candidate(name, files=spec.get("files"), version=spec.get("version"),
                                                  on_progress=progress, role=role)
        candidate[name] = (label.get("version", label.get("hash")), compiled)
    return baseline, candidate


# --------------------------------------------------------------------------- one run


@dataclass
class Outcome:
    """What one run did in one window of one query."""

    start: int | None = None
    rows: list[Any] | None = None
    fired: list[str] | None = None
    actions: list[Any] | None = None


class Run:
    """A scratch stream engine with the queries of one side, collecting what each window did."""

    def __init__(self, live: StreamEngine, rules: ReplayRules, definitions: list[Any], side: str,
                 where: dict[str, str] | None = None) -> None:
        self.side = side
        self.where = where or {}
        settings = live.settings.model_copy(update={"results_kept": 1})
        self.engine = StreamEngine(settings, rules_engine=rules, ontology=live.ontology, providers=live.providers)
        self.engine.share_static_graphs(live)
        self.engine.inline_fires = True
        self.windows: dict[tuple[str, int, int | None], Outcome] = {}
        self.errors: list[str] = []
        self.error_count = 0
        self.full = False
        self.not_replayable: list[dict[str, str]] = []
        for d in definitions:
            self._register(d)
        self.engine.subscribe(self._on_event)
        self.clock: int | None = None

    def _register(self, d: Any) -> None:
        binding = d.binding
        if binding is not None and binding.mode == "stateful":
            self.not_replayable.append({"query": d.name, "side": self.side,
                                        "reason": f"its binding to {binding.ruleset!r} is stateful: its decisions "
                                                  "depend on the session's history, so only its detections are compared"})
            binding = None
        where = self.where.get(d.name) or f"the served query {d.name}"
        try:
            self.engine.register(d.text, d.params, replace=True, binding=binding, report=d.report)
        except QueryParseError as exc:
            raise CandidateRefused(f"{where}.query: {exc.message}", f"{where}.query", line=exc.line,
                                   column=exc.column) from None
        except BindingError as exc:
            raise CandidateRefused(f"{where}: rules: {exc}", f"{where}.rules") from None
        except StreamError as exc:
            raise CandidateRefused(f"{where}: {exc}", where) from None

    def _on_event(self, event: dict[str, Any]) -> None:
        kind = event.get("kind")
        if kind == "error":
            self.error_count += 1
            if len(self.errors) < MAX_LISTED:
                self.errors.append(str(event.get("error")))
            return
        if kind not in ("result", "actions"):
            return
        window = event.get("window") or {}
        key = (str(event.get("query")), int(window.get("end", 0)), window.get("at"))
        if kind == "result" and not event.get("solutions"):
            return
        if key not in self.windows:
            if len(self.windows) >= MAX_KEPT:
                self.full = True
                return
            self.windows[key] = Outcome()
        outcome = self.windows[key]
        outcome.start = window.get("start", outcome.start)
        if kind == "result":
            outcome.rows = event.get("rows") or []
        else:
            outcome.fired = [str(r) for r in event.get("fired") or []]
            outcome.actions = list(event.get("actions") or [])

    def push(self, stream: str, ts: int, triples: list[Any] | None) -> None:
        """One message, after the heartbeats the ROS side would have given on the way to it."""
        if self.clock is not None:
            beat = ts - ts % HEARTBEAT_MS
            if beat > self.clock:
                self.engine.advance(beat)
        self.clock = ts if self.clock is None else max(self.clock, ts)
        if triples is not None:
            try:
                self.engine.push(stream, ts, triples)
            except StreamError as exc:
                self.error_count += 1
                if len(self.errors) < MAX_LISTED:
                    self.errors.append(f"message at {ts} on {stream}: {exc}")

    def finish(self, until: int | None) -> None:
        """Close the windows still open: up to the end of the period, else past the longest window."""
        if self.clock is None:
            return
        longest = max((w.get("range_ms") or 0 for q in self.engine.queries() for w in q.get("windows", [])), default=0)
        step = max((w.get("step_ms") or 0 for q in self.engine.queries() for w in q.get("windows", [])), default=0)
        self.engine.advance(until if until is not None else self.clock + longest + step + 1)

    def close(self) -> None:
        self.engine.close()


# --------------------------------------------------------------------------- comparing


def _rows_key(rows: list[Any] | None) -> list[str] | None:
    return None if rows is None else sorted(orjson.dumps(r, option=orjson.OPT_SORT_KEYS).decode() for r in rows)


@dataclass
class Comparison:
    """Both runs' windows compared: counts, per-rule counts and the changed windows."""

    max_changes: int
    detections: Counter[str] = field(default_factory=Counter)
    decisions: Counter[str] = field(default_factory=Counter)
    before: Counter[str] = field(default_factory=Counter)
    after: Counter[str] = field(default_factory=Counter)
    changes: list[dict[str, Any]] = field(default_factory=list)
    changed: int = 0

    def add(self, key: tuple[str, int, Any], a: Outcome | None, b: Outcome | None) -> None:
        a, b = a or Outcome(), b or Outcome()
        self.detections["before"] += a.rows is not None
        self.detections["after"] += b.rows is not None
        self.decisions["before"] += a.fired is not None
        self.decisions["after"] += b.fired is not None
        self.before.update(a.fired or [])
        self.after.update(b.fired or [])
        detection = _rows_key(a.rows) != _rows_key(b.rows)
        decision = (a.fired is None) != (b.fired is None) or (
            a.fired is not None and not same_outcome(a.fired, a.actions or [], b.fired or [], b.actions or []))
        self.detections["changed"] += detection
        self.decisions["changed"] += decision
        if not (detection or decision):
            return
        self.changed += 1
        if len(self.changes) < self.max_changes:
            window = {"start": a.start if a.start is not None else b.start, "end": key[1]}
            if key[2]:
                window["at"] = key[2]
            self.changes.append({"query": key[0], "window": window,
                                 "detection_changed": detection, "decision_changed": decision,
                                 "before": _shown(a), "after": _shown(b)})


def _shown(outcome: Outcome) -> dict[str, Any]:
    return {"rows": outcome.rows, "fired": outcome.fired, "actions": outcome.actions}


def compare(before: Run, after: Run, max_changes: int) -> Comparison:
    out = Comparison(max_changes)
    for key in sorted(set(before.windows) | set(after.windows), key=lambda k: (k[1], k[0], k[2] or 0)):
        out.add(key, before.windows.get(key), after.windows.get(key))
    return out


# --------------------------------------------------------------------------- the whole replay


def candidate_definitions(served: list[Any], candidates: dict[str, QueryCandidate]) -> list[Any]:
    """The served queries with the candidate's in place of (or besides) them."""
    from gateway.stream.services import QueryDefinition

    by_name = {d.name: d for d in served}
    out = [d for d in served if d.name not in candidates]
    for name, c in candidates.items():
        binding = by_name[name].binding if c.keep_binding and name in by_name else c.binding
        out.append(QueryDefinition(name, c.text, c.params, binding, c.report))
    return out


def run(engine: Any, live: StreamEngine, served: list[Any], recorded: RecordedInput, params: StreamReplayParams,
        on_progress: Progress | None = None) -> dict[str, Any]:
    """The whole stream replay of ``params``: compile the rule sets of both runs, register the
    queries on two scratch engines, push the recorded messages through both and compare."""
    check_limit(params.limit)
    progress = on_progress or (lambda _done, _total, _stage: None)
    progress(0, 1, "compile")
    definitions = candidate_definitions(served, params.queries)
    names = {d.binding.ruleset for d in served + definitions if d.binding is not None} | set(params.rulesets)
    baseline_rules, candidate_rules = compile_rulesets(engine, names, params.rulesets, params.role, progress)
    before = Run(live, ReplayRules(engine, baseline_rules), served, "before")
    try:
        after = Run(live, ReplayRules(engine, candidate_rules), definitions, "after",
                    {name: c.where for name, c in params.queries.items() if c.where})
        try:
            return _replay(before, after, recorded, params, progress, candidate_rules)
        finally:
            after.close()
    finally:
        before.close()


def _replay(before: Run, after: Run, recorded: RecordedInput, params: StreamReplayParams, progress: Progress,
            rulesets: dict[str, tuple[Any, Any]]) -> dict[str, Any]:
    matching = recorded.count()
    total = min(matching, params.limit)
    progress(0, total, "replay")
    done, unreplayable, listed, last = 0, 0, [], None
    for message in recorded.messages():
        if message.error:
            unreplayable += 1
            if len(listed) < MAX_LISTED:
                listed.append({"source": message.source, "stream": message.stream, "stamp_ms": message.ts,
                               "reason": message.error})
        before.push(message.stream, message.ts, message.before)
        after.push(message.stream, message.ts, message.after)
        last = message.ts
        done += 1
        if done % PROGRESS_EVERY == 0:
            progress(done, total, "replay")
    until = params.until_ms if matching <= params.limit else None
    before.finish(until)
    after.finish(until)
    progress(done, max(total, done), "replay")
    result = compare(before, after, params.max_changes)
    notes = []
    if done == 0:
        notes.append("no recorded message matches the selection: nothing was replayed")
    if matching > params.limit:
        notes.append(f"{matching} recorded messages match the selection: the first {params.limit} were replayed "
                     f"(up to stamp {last}; replay again with since after it for the rest)")
    if before.full or after.full:
        notes.append(f"more than {MAX_KEPT} windows with results: the later ones were not compared")
    rules = [{"rule": r, "before": result.before.get(r, 0), "after": result.after.get(r, 0)}
             for r in sorted(set(result.before) | set(result.after))]
    out: dict[str, Any] = {
        "source": recorded.source, "replayed": done, "matching": matching, "selected": total,
        "candidate": {"queries": sorted(params.queries), "mappings": sorted(params.mappings),
                      "rulesets": {n: ({"hash": rulesets[n][0]} if isinstance(rulesets[n][0], str)
                                       else {"version": rulesets[n][0]}) for n in sorted(params.rulesets)}},
        "detections": {k: result.detections.get(k, 0) for k in ("before", "after", "changed")},
        "decisions": {k: result.decisions.get(k, 0) for k in ("before", "after", "changed")},
        "changed": result.changed, "rules": rules, "changes": result.changes,
        "changes_truncated": result.changed > len(result.changes),
        "not_replayable": unreplayable, "not_replayable_messages": listed,
        "not_replayable_bindings": before.not_replayable + after.not_replayable,
        "errors": {"before": before.error_count, "after": after.error_count,
                   "listed": [f"before: {e}" for e in before.errors[:10]] + [f"after: {e}" for e in after.errors[:10]]},
    }
    if notes:
        out["note"] = " ".join(notes)
    return out
