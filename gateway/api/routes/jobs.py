"""``/api/jobs``: follow, list and cancel build jobs (asynchronous deploys and validations).

A deploy or validate sent with ``Prefer: respond-async`` (or ``?async=true``) answers ``202`` with
the job; ``GET /api/jobs/{id}`` then tells its state, the build's stage and progress, and in the end
its result (the deployed version, or ``{valid, errors}``) or its error — the body the synchronous
call would have answered with. Any gateway process answers (records are in the Information State).
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Query

from gateway.api.deps import Author, Caller, JobsDep
from gateway.api.errors import engine_error_status
from gateway.api.jsonio import JSON, JsonRoute

router = APIRouter(tags=["build jobs"], route_class=JsonRoute)


def _with_status(job: dict) -> dict:
    """A failed job's error carries the HTTP ``status`` the synchronous call would have answered."""
    if job.get("error"):
        job = {**job, "error": {**job["error"], "status": engine_error_status(job["error"].get("kind", ""))}}
    return job


@router.get("/api/jobs")
def list_jobs(jobs: JobsDep, _: Caller, ruleset: str | None = None,
              limit: Annotated[int, Query(ge=1, le=500)] = 50) -> JSON:
    """The latest build jobs, newest first (``?ruleset=`` for one rule set's)."""
    return JSON({"jobs": [_with_status(j) for j in jobs.list(ruleset, limit)]})


@router.get("/api/jobs/{job_id}")
def get_job(job_id: str, jobs: JobsDep, _: Caller) -> JSON:
    """One job: ``status`` (queued, running, succeeded, failed, cancelled), ``progress``
    (``{stage, done, total}``), ``result`` or ``error`` (with the ``status`` the synchronous call
    would have answered: 422 compile errors, 409 conflict, 503 resources...)."""
    return JSON(_with_status(jobs.get(job_id)))


@router.delete("/api/jobs/{job_id}")
def cancel_job(job_id: str, jobs: JobsDep, who: Author) -> JSON:
    """Cancel a job: a queued one at once (200, ``cancelled``); a running build is asked to stop
    (202, ``cancel_requested``: it ends ``cancelled`` if it was still compiling, else it finishes);
    409 for a finished job or one another gateway process runs."""
    job = _with_status(jobs.cancel(job_id, who.name))
    return JSON(job, status_code=202 if job["status"] == "running" else 200)
