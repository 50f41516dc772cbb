"""Build jobs: deploys and validations that run in the background and report their progress.

Why: compiling thousands of rules takes a minute the first time, longer than HTTP clients, load
balancers and people like to wait on one request. A client that asks for it (``Prefer:
respond-async`` or ``?async=true``) gets ``202 Accepted`` and a job at once, then follows the job:
its state (queued → running → succeeded | failed | cancelled), the build's stage and how far it is,
and in the end the deployed version or the compile errors (with file, line and column) — the same
answers the synchronous call gives.

Jobs run one at a time per process (a build is CPU- and memory-bound: two at once only make both
slower and double the peak heap), in the process that accepted them. Their records go to the
Information State (collection ``jobs``), so any gateway process answers ``GET /api/jobs/{id}``; a
job whose process died while it was queued or running is reported as failed with that reason.
Serving is never blocked: the old version answers until the new one is swapped in.
"""

from __future__ import annotations

import logging
import threading
import time
import uuid
from collections import OrderedDict, deque
from collections.abc import Callable
from datetime import datetime, timezone
from typing import Any

from gateway.base import priority
from gateway.engine.errors import BuildCancelled, EngineError

log = logging.getLogger(__name__)

JOBS = "jobs"
KINDS = ("deploy", "validate", "replay")
FINISHED = ("succeeded", "failed", "cancelled")
# a running build stops at its next progress report while it is still in one of these stages
# (later, the version is being tested, stored and swapped in: that finishes)
CANCELLABLE_STAGES = ("parse", "compile", "load", "assemble", "replay")
PROGRESS_WRITE_INTERVAL_S = 0.5  # progress reaches the store at most twice a second
LOST_AFTER_S = 30.0  # an unfinished job of a process that is gone, untouched this long, is lost


class JobError(Exception):
    """A job request the service refuses (``status``: the HTTP status that fits)."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


def _now() -> str:
    return datetime.now(timezone.utc).isoformat()


class JobRecords:
    """Where job records live: the ``jobs`` collection when there is a store, else this process only."""

    def __init__(self, db: Any = None, keep: int = 500) -> None:
        self.db = db
        self._memory: OrderedDict[str, dict[str, Any]] = OrderedDict()
        self._keep = keep
        self._lock = threading.Lock()
        if db is not None:
            try:
                db[JOBS].create_index([("ruleset", 1), ("created_at", -1)])
            except Exception as exc:  # an index is an optimisation; jobs work without it
                log.warning("jobs index not created: %s", exc)

    def write(self, job: dict[str, Any]) -> None:
        with self._lock:
            self._memory[job["id"]] = dict(job)
            self._memory.move_to_end(job["id"])
            while len(self._memory) > self._keep:
                self._memory.popitem(last=False)
        if self.db is not None:
            try:
                self.db[JOBS].replace_one({"_id": job["id"]}, {"_id": job["id"], **job}, upsert=True)
            except Exception as exc:  # the job goes on; this process still answers for it
                log.warning("job %s not recorded: %s", job["id"], exc)

    def read(self, job_id: str) -> dict[str, Any] | None:
        with self._lock:
            if job_id in self._memory:
                return dict(self._memory[job_id])
        if self.db is None:
            return None
        doc = self.db[JOBS].find_one({"_id": job_id})
        if doc is not None:
            doc.pop("_id", None)
        return doc

    def recent(self, ruleset: str | None, limit: int) -> list[dict[str, Any]]:
        if self.db is None:
            with self._lock:
                jobs = [dict(j) for j in self._memory.values() if ruleset is None or j["ruleset"] == ruleset]
            return sorted(jobs, key=lambda j: j["created_at"], reverse=True)[:limit]
        query = {"ruleset": ruleset} if ruleset else {}
        docs = list(self.db[JOBS].find(query).sort("created_at", -1).limit(limit))
        for doc in docs:
            doc.pop("_id", None)
        return docs


class JobService:
    """Accepts build jobs, runs them one at a time on a worker thread, and answers for them.

    ``engine`` is the rules engine (:class:`gateway.engine.engine.Engine`); ``alive(process)`` says
    whether another gateway process is still running (for jobs that process accepted).
    """

    def __init__(self, engine: Any, records: JobRecords, process: str,
                 alive: Callable[[str], bool] | None = None, max_queued: int = 16) -> None:
        self.engine = engine
        self.records = records
        self.process = process
        self.alive = alive or (lambda _process: True)
        self.max_queued = max_queued
        self._queue: deque[tuple[dict[str, Any], Any]] = deque()  # (job, files | a replay's task)
        self._jobs: dict[str, dict[str, Any]] = {}
        self._cond = threading.Condition()
        self._closed = False
        self._thread = threading.Thread(target=self._work, name="build-jobs", daemon=True)
        self._thread.start()

    # ---- requests --------------------------------------------------------------------------------
    def submit(self, kind: str, ruleset: str, files: dict[str, str], *, author: str = "anonymous",
               comment: str = "", base_version: int | None = None, force: bool = False,
               role: str | None = None,
               task: Callable[[Callable[[int, int, str], None]], dict[str, Any]] | None = None) -> dict[str, Any]:
        """A new queued job; the build starts when the jobs before it in this process are done.

        A ``replay`` job runs ``task(progress)`` (the replay, bound to its request by the caller)
        and its result is what ``task`` returns."""
        if kind not in KINDS:
            raise JobError(422, f"kind must be one of {', '.join(KINDS)}, not {kind!r}")
        if (kind == "replay") != (task is not None):
            raise JobError(422, "a replay job needs its task, and only a replay job has one")
        job = {"id": uuid.uuid4().hex, "kind": kind, "ruleset": ruleset, "status": "queued",
               "author": author, "role": role, "comment": comment, "base_version": base_version, "force": force,
               "process": self.process, "created_at": _now(), "started_at": None, "finished_at": None,
               "updated_at": _now(), "progress": None, "result": None, "error": None}
        with self._cond:
            if self._closed:
                raise JobError(503, "the gateway is shutting down; try again on another process")
            if len(self._queue) >= self.max_queued:
                raise JobError(429, f"{len(self._queue)} build jobs are already waiting in this process "
                                    f"(engine.max_queued_jobs = {self.max_queued}); try again later")
            self._jobs[job["id"]] = job
            self._queue.append((job, task if task is not None else dict(files)))
            self.records.write(job)
            self._cond.notify()
        return dict(job)

    def get(self, job_id: str) -> dict[str, Any]:
        with self._cond:
            if job_id in self._jobs:
                return dict(self._jobs[job_id])
        job = self.records.read(job_id)
        if job is None:
            raise JobError(404, f"no job {job_id!r}")
        return self._maybe_lost(job)

    def list(self, ruleset: str | None = None, limit: int = 50) -> list[dict[str, Any]]:
        """The latest jobs; this process's unfinished ones as they are now (their records are
        written at most twice a second)."""
        recorded = self.records.recent(ruleset, max(1, min(limit, 500)))
        with self._cond:
            live = {job_id: dict(job) for job_id, job in self._jobs.items()}
        return [self._maybe_lost(live.get(j["id"], j)) for j in recorded]

    def cancel(self, job_id: str, by: str = "anonymous") -> dict[str, Any]:
        """Cancels a job of this process. A queued job ends ``cancelled`` at once; a running build
        is asked to stop (``cancel_requested``): it stops at its next progress report (within
        about half a second) while it is still compiling, and ends ``cancelled``; past compiling
        (testing, storing, swapping in) it finishes. A finished job stays as it ended."""
        with self._cond:
            job = self._jobs.get(job_id)
            if job is None:
                other = self.records.read(job_id)
                if other is None:
                    raise JobError(404, f"no job {job_id!r}")
                if other.get("process") == self.process or other.get("status") in FINISHED:
                    raise JobError(409, f"job {job_id} is {other['status']}: a finished job cannot be cancelled")
                raise JobError(409, f"job {job_id} belongs to gateway process {other['process']}; "
                                    "cancel it there")
            if job["status"] == "running":
                job.update(cancel_requested=True, cancel_requested_by=by, updated_at=_now())
                self.records.write(job)
                return dict(job)
            self._queue = deque((j, f) for j, f in self._queue if j["id"] != job_id)
            self._finish(job, "cancelled", error={"kind": "cancelled", "error": f"cancelled by {by}"})
            return dict(job)

    def close(self, timeout_s: float = 5.0) -> None:
        """Refuse new jobs, cancel the queued ones, and give the running build a moment to end."""
        with self._cond:
            self._closed = True
            for job, _files in self._queue:
                self._finish(job, "cancelled", error={"kind": "cancelled", "error": "the gateway process stopped"})
            self._queue.clear()
            self._cond.notify_all()
        self._thread.join(timeout_s)

    # ---- running ---------------------------------------------------------------------------------
    def _work(self) -> None:
        priority.lower_this_thread()
        while True:
            with self._cond:
                while not self._queue and not self._closed:
                    self._cond.wait()
                if self._closed and not self._queue:
                    return
                job, files = self._queue.popleft()
                job.update(status="running", started_at=_now(), updated_at=_now())
                self.records.write(job)
            self._run(job, files)

    def _run(self, job: dict[str, Any], files: Any) -> None:
        progress = self._progress_writer(job)
        try:
            if job["kind"] == "replay":
                outcome = files(progress)  # type: ignore[operator]  # the replay's task (see submit)
            elif job["kind"] == "deploy":
                info = self.engine.deploy(job["ruleset"], files, author=job["author"], comment=job["comment"],
                                          base_version=job["base_version"], force=job["force"],
                                          on_progress=progress, role=job.get("role"))
                outcome: dict[str, Any] = {"version": info.to_dict()}
            else:
                errors = self.engine.validate(job["ruleset"], files, on_progress=progress, role=job.get("role"))
                # the synchronous validate's answer ({"ok", "errors"}); "valid" is its older name here
                outcome = {"ok": not errors, "valid": not errors, "errors": [e.to_dict() for e in errors]}
        except BuildCancelled as exc:
            with self._cond:
                self._finish(job, "cancelled", error=exc.to_dict())
            return
        except EngineError as exc:
            with self._cond:
                self._finish(job, "failed", error=exc.to_dict())
            return
        except Exception as exc:  # a job must end with a record, whatever broke
            log.exception("build job %s failed", job["id"])
            with self._cond:
                self._finish(job, "failed", error={"kind": "internal", "error": f"{type(exc).__name__}: {exc}"})
            return
        with self._cond:
            self._finish(job, "succeeded", result=outcome)

    def _progress_writer(self, job: dict[str, Any]) -> Callable[[int, int, str], None]:
        last = [0.0, ""]  # when the record was last written, and at which stage

        def report(done: int, total: int, stage: str) -> None:
            with self._cond:
                if job.get("cancel_requested") and stage in CANCELLABLE_STAGES:
                    raise BuildCancelled(f"cancelled by {job.get('cancel_requested_by', 'anonymous')} "
                                         f"while {stage}: nothing was deployed")
                job["progress"] = {"stage": stage, "done": done, "total": total}
                job["updated_at"] = _now()
                now = time.monotonic()
                if now - last[0] >= PROGRESS_WRITE_INTERVAL_S or done >= total or stage != last[1]:
                    last[0], last[1] = now, stage  # a new stage is always written: other processes see it
                    self.records.write(job)
        return report

    def _finish(self, job: dict[str, Any], status: str, *, result: dict[str, Any] | None = None,
                error: dict[str, Any] | None = None) -> None:
        job.update(status=status, result=result, error=error, finished_at=_now(), updated_at=_now())
        self.records.write(job)
        self._jobs.pop(job["id"], None)  # finished jobs are answered from the records

    def _maybe_lost(self, job: dict[str, Any]) -> dict[str, Any]:
        """An unfinished job of another process that died is reported as failed, not as running forever."""
        if job["status"] in FINISHED or job.get("process") == self.process:
            return job
        try:
            age = (datetime.now(timezone.utc) - datetime.fromisoformat(job["updated_at"])).total_seconds()
        except (KeyError, TypeError, ValueError):
            age = LOST_AFTER_S
        if age >= LOST_AFTER_S and not self.alive(job.get("process", "")):
            return {**job, "status": "failed",
                    "error": {"kind": "lost", "error": f"gateway process {job.get('process')} stopped before "
                                                       "the job finished; submit it again"}}
        return job
