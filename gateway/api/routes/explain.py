"""Explain and trace: why each rule fired or did not, and one chain end to end.

    GET  /api/decisions/{id}/explain       a recorded decision, on the version that made it
    POST /api/rulesets/{name}/explain      {"facts", "files"?, "version"?}: a draft, a version or the live one
    GET  /api/traces/{correlation_id}      everything recorded for one chain, in time order

Explaining is a dry run (nothing recorded, no action performed); its diagnostic queries are built
once per version (the first explain of a version waits for that build, later ones take
milliseconds). See :mod:`gateway.engine.explain` and :mod:`gateway.store.traces`.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path as PathParam
from pydantic import BaseModel, ConfigDict, Field

from gateway.api.deps import Caller, DecisionsDep, EngineDep, SettingsDep, StoreDep
from gateway.api.errors import ApiError
from gateway.api.jsonio import JSON, JsonRoute
from gateway.api.routes.decisions import recorded_decision
from gateway.api.routes.rulesets import MAX_FILES, RuleSetName, facts_from_body
from gateway.engine.replay import not_replayable
from gateway.store.decisions import READ_OWN_S
from gateway.store.store import StoreUnavailable
from gateway.store.traces import trace

router = APIRouter(tags=["explain and trace"], route_class=JsonRoute)


class ExplainBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    facts: list[dict[str, Any]] = Field(default_factory=list)
    files: dict[str, str] | None = Field(default=None, min_length=1, max_length=MAX_FILES,
                                         description="a draft to explain (default: the live version)")
    version: int | None = Field(default=None, ge=1, description="a stored version (default: the live one)")


@router.post("/api/rulesets/{name}/explain")
def explain_facts(name: RuleSetName, body: ExplainBody, engine: EngineDep, settings: SettingsDep, who: Caller) -> JSON:
    """For every rule: ``fired: true`` with each match's facts, or ``fired: false`` with the
    ``condition`` that stopped it (as written: the DSL sentence, the DRL pattern or the table cell,
    with its position), the failed ``constraint``, the ``closest`` fact and a ``reason`` in words.
    Not a decision. 422 (file, line, column) for a draft that does not compile."""
    if body.files is not None and body.version is not None:
        raise ApiError(422, "explain a draft ('files') or a stored 'version', not both",
                       errors=[{"field": "files", "message": "files or version"}])
    facts = facts_from_body({"facts": body.facts}, settings.engine.max_facts)
    return JSON(engine.explain(name, facts, files=body.files, version=body.version, role=who.role))


@router.get("/api/decisions/{decision_id}/explain")
def explain_decision(decision_id: str, engine: EngineDep, decisions: DecisionsDep, _: Caller) -> JSON:
    """A recorded decision explained on its version and its facts, with what was recorded; a
    decision whose facts were cut or that was made in a session says that its explanation sees only
    the recorded facts."""
    found = recorded_decision(decisions, decision_id)
    out = engine.explain(found["ruleset"], list(found.get("facts") or []), version=int(found["version"]))
    out.update(decision_id=decision_id, recorded={"fired": found.get("fired"), "actions": found.get("actions"),
                                                  "at": found.get("at")})
    caveat = not_replayable(found)
    if caveat:
        out["note"] = f"explained on the recorded facts only: {caveat}"
    return JSON(out)


@router.get("/api/traces/{correlation_id}")
def get_trace(correlation_id: Annotated[str, PathParam(max_length=200)], store: StoreDep, _: Caller) -> JSON:
    """Everything recorded for one chain, oldest first: sensor message → RDF item → query result →
    decision → robot actions and their outcomes (a REST, KIE or ROS service fire: the decision and
    its actions), each with ``since_previous_ms``, and the ``hops`` between kinds."""
    store.settle(READ_OWN_S)  # what this process recorded before the request is in the chain
    try:
        found = trace(store.db, correlation_id)
    except StoreUnavailable as exc:
        raise ApiError(503, str(exc)) from None
    if found is None:
        raise ApiError(404, f"no decision was recorded with correlation id {correlation_id!r}",
                       correlation_id=correlation_id)
    return JSON(found)
