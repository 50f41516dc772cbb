"""``POST /api/streams/replay``: what a candidate query, mapping or rule set would have detected and
decided on the sensor input the gateway recorded.

The core is :mod:`gateway.stream.replay`; this route reads the request (each candidate checked
where it is named), and runs the replay now (in the threadpool) or, with ``Prefer: respond-async``,
as a build job of kind ``replay`` (progress, cancel), like the rule-set replay. A stream replay
records nothing, sends nothing to a robot and changes nothing live.
"""

from __future__ import annotations

import json
from typing import Any

from fastapi import APIRouter, Request
from pydantic import BaseModel, ConfigDict, Field

from gateway.api.deps import Caller, EngineDep, GatewayDep, JobsDep, iso_datetime
from gateway.api.errors import ApiError
from gateway.api.jsonio import JSON, JsonRoute
from gateway.api.routes.mappings import DraftBody
from gateway.api.routes.replay import run_replay
from gateway.api.routes.rulesets import MAX_FILES
from gateway.rdf.mapping import Mapper, MappingError
from gateway.stream import replay
from gateway.stream.lexer import QueryParseError
from gateway.stream.query import ParamSpec, parse_query
from gateway.stream.rules import BindingError, RuleBinding

router = APIRouter(tags=["replay"], route_class=JsonRoute)
MAX_CANDIDATES = 50
JOB_SUBJECT = "streams"  # a stream replay job's "ruleset": it is about the streams, not one rule set


class QueryDraft(BaseModel):
    """A candidate continuous query: its C-SPARQL text (its REGISTER name says which query it
    replaces, or adds) and the registration's options. Without ``rules`` the served query's
    binding is kept; ``"rules": null`` replays it unbound."""

    model_config = ConfigDict(extra="forbid")
    query: str = Field(min_length=1, max_length=200_000)
    params: dict[str, dict[str, Any]] | None = None
    rules: dict[str, Any] | None = None
    report: str | None = Field(default=None, max_length=200)


class RuleSetDraft(BaseModel):
    """A candidate rule set: a draft (``files``) or a stored ``version``."""

    model_config = ConfigDict(extra="forbid")
    files: dict[str, str] | None = Field(default=None, min_length=1, max_length=MAX_FILES)
    version: int | None = Field(default=None, ge=1)


class StreamReplayBody(BaseModel):
    """The period of recorded input (by event time, oldest first) and the candidate."""

    model_config = ConfigDict(extra="forbid")
    since: str | None = Field(default=None, description="ISO-8601, inclusive (event time)")
    until: str | None = Field(default=None, description="ISO-8601, exclusive (event time)")
    streams: list[str] | None = Field(default=None, min_length=1, max_length=50)
    limit: int = Field(default=replay.DEFAULT_LIMIT, description=f"recorded messages, at most {replay.MAX_LIMIT}")
    max_changes: int = Field(default=replay.DEFAULT_MAX_CHANGES, ge=0, le=10_000)
    queries: list[QueryDraft] | None = Field(default=None, max_length=MAX_CANDIDATES)
    rulesets: dict[str, RuleSetDraft] | None = Field(default=None, max_length=MAX_CANDIDATES)
    mappings: dict[str, DraftBody] | None = Field(default=None, max_length=MAX_CANDIDATES)


def _params(raw: dict[str, dict[str, Any]] | None, where: str) -> list[ParamSpec] | None:
    if raw is None:
        return None
    out = []
    for name, spec in raw.items():
        if ("sparql" in spec) == ("value" in spec):
            raise ApiError(422, "give exactly one of 'sparql' or 'value'", field=f"{where}.params.{name}")
        value = spec.get("value")
        if value is not None and not isinstance(value, str):
            value = json.dumps(value)
        out.append(ParamSpec(name=name.lstrip("?$"), sparql=spec.get("sparql"), value=value))
    return out


def _query_candidates(drafts: list[QueryDraft]) -> dict[str, replay.QueryCandidate]:
    """The candidate queries by the name their text registers; 422 naming the draft that is wrong."""
    out: dict[str, replay.QueryCandidate] = {}
    for i, draft in enumerate(drafts):
        where = f"queries[{i}]"
        params = _params(draft.params, where)
        try:
            name = parse_query(draft.query, params).name
        except QueryParseError as exc:
            raise ApiError(422, f"{where}.query: {exc.message}", field=f"{where}.query", line=exc.line,
                           column=exc.column) from None
        if name in out:
            raise ApiError(422, f"two candidates register the query {name!r}", field=f"{where}.query")
        keep = "rules" not in draft.model_fields_set
        try:
            binding = None if keep or draft.rules is None else RuleBinding.from_dict(draft.rules, f"{where}.rules")
        except BindingError as exc:
            raise ApiError(422, str(exc), field=f"{where}.rules") from None
        out[name] = replay.QueryCandidate(draft.query, params, binding, draft.report, keep_binding=keep, where=where)
    return out


def _rule_set_candidates(drafts: dict[str, RuleSetDraft]) -> dict[str, dict[str, Any]]:
    for name, draft in drafts.items():
        if (draft.files is None) == (draft.version is None):
            raise ApiError(422, f"rulesets.{name}: give 'files' (a draft) or 'version', one of the two",
                           field=f"rulesets.{name}")
    return {name: {"files": d.files, "version": d.version} for name, d in drafts.items()}


def _candidate_mapper(gateway: Any, drafts: dict[str, DraftBody]) -> tuple[Mapper | None, dict[str, Any]]:
    """The live mappings with the candidate's in place: each checked as a save would be (422 with
    where, and line/column for YAML text), and used by a subscription (else 422: it maps nothing)."""
    if not drafts:
        return None, {}
    used = {s.mapping for s in gateway.settings.ros.subscriptions if isinstance(s.mapping, str)}
    live: Mapper = gateway.mapper
    nodes = {}
    for name, draft in drafts.items():
        if name not in used:
            raise ApiError(422, f"mappings.{name}: no ROS subscription maps its messages with {name!r}, so its "
                                f"recorded messages cannot be told apart; subscriptions use {sorted(used)}",
                           field=f"mappings.{name}")
        spec, text = draft.draft()
        try:
            nodes[name] = gateway.mappings.check(name, spec)
        except MappingError as exc:
            line, column = text.locate(exc.where) if text is not None else (None, None)
            raise ApiError(422, f"mappings.{name}: {exc.message}", field=f"mappings.{name}", where=exc.where,
                           line=line, column=column) from None
    return Mapper({**live.mappings, **nodes}, live.prefixes), nodes


def stream_replay_params(body: StreamReplayBody, gateway: Any, role: str | None) -> tuple[replay.StreamReplayParams,
                                                                                           Mapper | None]:
    """The core's parameters and the candidate's mapper, or ApiError 422 naming the field."""
    if not 1 <= body.limit <= replay.MAX_LIMIT:
        raise ApiError(422, f"limit {body.limit}: a stream replay takes 1 to {replay.MAX_LIMIT} recorded messages",
                       errors=[{"field": "limit", "message": f"between 1 and {replay.MAX_LIMIT}"}])
    since, until = iso_datetime("since", body.since), iso_datetime("until", body.until)
    if since and until and since >= until:
        raise ApiError(422, "since must be before until", errors=[{"field": "since", "message": "after until"}])
    mapper, nodes = _candidate_mapper(gateway, body.mappings or {})
    params = replay.StreamReplayParams(
        since_ms=replay.epoch_ms(since), until_ms=replay.epoch_ms(until),
        streams=tuple(body.streams) if body.streams else None, limit=body.limit, max_changes=body.max_changes,
        queries=_query_candidates(body.queries or []), rulesets=_rule_set_candidates(body.rulesets or {}),
        mappings=nodes, role=role)
    return params, mapper


@router.post("/api/streams/replay")
def replay_streams(body: StreamReplayBody, request: Request, gateway: GatewayDep, engine: EngineDep, jobs: JobsDep,
                   who: Caller) -> JSON:
    """Push the recorded sensor input of a period through the served queries as they are and with
    the candidate (``queries``, ``rulesets``, ``mappings``), and answer the windows whose detection
    or decision differs: ``{"replayed", "detections", "decisions", "rules", "changes", ...}``.
    422 naming the field for a candidate that does not parse or compile; 404 for an unknown rule set
    version. ``Prefer: respond-async``: 202 and a ``replay`` job."""
    if gateway.store is None:
        raise ApiError(503, "the Information State is not configured on this gateway: nothing was recorded")
    params, mapper = stream_replay_params(body, gateway, who.role)
    recorded = replay.RecordedInput(gateway.store.db, params, gateway.settings.ros.subscriptions, gateway.mapper,
                                    mapper)

    def task(progress: Any = None) -> dict[str, Any]:
        return replay.run(engine, gateway.streams, gateway.queries.definitions(), recorded, params,
                          on_progress=progress)

    return run_replay(request, jobs, JOB_SUBJECT, who.name, task)
