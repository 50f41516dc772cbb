"""``POST /api/rulesets/{name}/replay``: what a candidate would have decided on recorded decisions.

The core is :mod:`gateway.engine.replay`; this route checks the request, and runs it now (in the
threadpool) or, with ``Prefer: respond-async``, as a build job of kind ``replay`` (progress, cancel).
A replay performs no action, records no decision and changes nothing live.
"""

from __future__ import annotations

import threading
from typing import Any, Callable

from fastapi import APIRouter, Request
from pydantic import BaseModel, ConfigDict, Field

from gateway.api.deps import Caller, DecisionsDep, EngineDep, JobsDep, iso_datetime, wants_async
from gateway.api.errors import ApiError
from gateway.api.jsonio import JSON, JsonRoute
from gateway.api.routes.rulesets import MAX_FILES, RuleSetName, accepted
from gateway.engine import replay
from gateway.store.store import StoreUnavailable

router = APIRouter(tags=["replay"], route_class=JsonRoute)
MAX_SYNC_REPLAYS = 2  # synchronous replays at once per process (each holds a worker thread); more: 429
running = threading.BoundedSemaphore(MAX_SYNC_REPLAYS)  # shared with the stream replay


class ReplayBody(BaseModel):
    """The candidate (``files``: an undeployed draft, or ``version``: a stored version) and which
    recorded decisions of the rule set to replay on it (newest first)."""

    model_config = ConfigDict(extra="forbid")
    files: dict[str, str] | None = Field(default=None, min_length=1, max_length=MAX_FILES)
    version: int | None = Field(default=None, ge=1)
    since: str | None = Field(default=None, description="ISO-8601, inclusive")
    until: str | None = Field(default=None, description="ISO-8601, exclusive")
    origin: str | None = Field(default=None, max_length=40, description="rest, kie, stream, ros, workflow, api")
    limit: int = Field(default=replay.DEFAULT_LIMIT, description=f"at most {replay.MAX_LIMIT}")
    max_changes: int = Field(default=replay.DEFAULT_MAX_CHANGES, ge=0, le=10_000,
                             description="changed decisions listed in 'changes' (all are counted)")


def replay_params(body: ReplayBody, role: str | None = None) -> replay.ReplayParams:
    """The engine's parameters, or ApiError 422 naming the field that is wrong."""
    if (body.files is None) == (body.version is None):
        raise ApiError(422, "give the candidate as 'files' (a draft) or as 'version', one of the two",
                       errors=[{"field": "files", "message": "files or version, not both or neither"}])
    if not 1 <= body.limit <= replay.MAX_LIMIT:
        raise ApiError(422, f"limit {body.limit}: a replay takes 1 to {replay.MAX_LIMIT} decisions",
                       errors=[{"field": "limit", "message": f"between 1 and {replay.MAX_LIMIT}"}])
    since, until = iso_datetime("since", body.since), iso_datetime("until", body.until)
    if since and until and since >= until:
        raise ApiError(422, "since must be before until", errors=[{"field": "since", "message": "after until"}])
    return replay.ReplayParams(files=body.files, version=body.version, since=since, until=until, origin=body.origin,
                               limit=body.limit, max_changes=body.max_changes, role=role)


@router.post("/api/rulesets/{name}/replay")
def replay_decisions(name: RuleSetName, body: ReplayBody, request: Request, engine: EngineDep,
                     decisions: DecisionsDep, jobs: JobsDep, who: Caller) -> JSON:
    """Re-fire recorded decisions of ``name`` on the candidate and compare the rules fired and the
    actions with what was recorded: ``{"ruleset", "candidate", "replayed", "changed", "unchanged",
    "failed", "rules": [{"rule", "before", "after"}], "changes": [...], "not_replayable", ...}``.
    422 with ``errors`` (file, line, column) if the draft does not compile; 404 for an unknown
    version; 422 for a limit over 100,000. ``Prefer: respond-async``: 202 and a ``replay`` job."""
    params = replay_params(body, who.role)
    engine.versions(name)  # 404 for a rule set that never existed, before any work

    def task(progress: Any = None) -> dict[str, Any]:
        return replay.run(engine, decisions, name, params, on_progress=progress)

    return run_replay(request, jobs, name, who.name, task)


def run_replay(request: Request, jobs: Any, subject: str, author: str, task: Callable[..., dict[str, Any]]) -> JSON:
    """Run a replay ``task`` (rule-set or stream replay) the one way: a ``replay`` build job with
    ``Prefer: respond-async``, else now, at most MAX_SYNC_REPLAYS at once per process (429 +
    Retry-After beyond), a store away being 503."""
    if wants_async(request):
        return accepted(jobs.submit("replay", subject, {}, author=author, task=task))
    if not running.acquire(blocking=False):
        raise ApiError(429, f"{MAX_SYNC_REPLAYS} replays are already running on this gateway process; try again "
                            "shortly, or send Prefer: respond-async to queue it as a job",
                       headers={"Retry-After": "5"})
    try:
        return JSON(task())
    except StoreUnavailable as exc:
        raise ApiError(503, str(exc)) from None
    finally:
        running.release()
