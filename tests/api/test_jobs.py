"""Build jobs over REST: an asynchronous deploy or validation answers 202 at once and is followed
to the same result the synchronous call gives (real JVM, real MongoDB-protocol server)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest

from gateway.runtime.jobs import JobRecords, JobService

from api_helpers import BROKEN, FACTS, files

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "bench" / "peers"))
import growth_rules  # noqa: E402

ASYNC = {"Prefer": "respond-async"}


def follow(client, location: str, timeout_s: float = 120.0) -> dict:
    """Poll a job until it ends (the test's own safety limit, not a timing assertion)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job = client.get(location).json()
        if job["status"] in ("succeeded", "failed", "cancelled"):
            return job
        time.sleep(0.05)
    pytest.fail(f"job {location} did not end")


def said(result: dict) -> list[str]:
    return [a["params"]["text"] for a in result["actions"] if a["module"] == "say"]


def test_an_async_deploy_is_accepted_then_live(client):
    response = client.put("/api/rulesets/jobs-a", json={"files": files("async"), "comment": "by job"}, headers=ASYNC)
    assert response.status_code == 202
    job = response.json()
    assert job["status"] in ("queued", "running") and job["kind"] == "deploy" and job["ruleset"] == "jobs-a"
    assert response.headers["location"] == f"/api/jobs/{job['id']}"
    done = follow(client, response.headers["location"])
    assert done["status"] == "succeeded", done
    assert done["result"]["version"]["version"] == 1
    assert done["progress"]["stage"] and done["progress"]["done"] == done["progress"]["total"]
    fired = client.post("/api/rulesets/jobs-a/fire", json={"facts": FACTS}).json()
    assert "Welcome c1 (async)" in said(fired)
    listed = client.get("/api/jobs", params={"ruleset": "jobs-a"}).json()["jobs"]
    assert [j["id"] for j in listed] == [job["id"]]


def test_an_async_deploy_that_does_not_compile_fails_with_the_errors_and_changes_nothing(client):
    assert client.put("/api/rulesets/jobs-b", json={"files": files("b1")}).status_code == 201
    response = client.put("/api/rulesets/jobs-b?async=true", json={"files": BROKEN, "base_version": 1})
    done = follow(client, response.headers["location"])
    assert done["status"] == "failed"
    assert done["error"]["errors"][0]["file"] == "greet.drl" and done["error"]["errors"][0]["line"] > 0
    assert client.get("/api/rulesets/jobs-b").json()["version"] == 1


def test_a_stale_base_version_fails_the_job_as_a_conflict(client):
    assert client.put("/api/rulesets/jobs-c", json={"files": files("c1")}).status_code == 201
    assert client.put("/api/rulesets/jobs-c", json={"files": files("c2"), "base_version": 1}).status_code == 201
    response = client.put("/api/rulesets/jobs-c", json={"files": files("c3"), "base_version": 1}, headers=ASYNC)
    done = follow(client, response.headers["location"])
    assert done["status"] == "failed" and done["error"]["kind"] == "conflict", done["error"]
    assert done["error"]["status"] == 409


def test_an_async_validation_reports_errors_without_deploying(client):
    response = client.post("/api/rulesets/jobs-d/validate", json={"files": BROKEN}, headers=ASYNC)
    assert response.status_code == 202
    done = follow(client, response.headers["location"])
    assert done["status"] == "succeeded" and done["result"]["valid"] is False
    assert done["result"]["errors"][0]["file"] == "greet.drl"
    assert client.get("/api/rulesets/jobs-d").status_code == 404


def test_unknown_jobs_and_finished_jobs_are_told_clearly(client):
    assert client.get("/api/jobs/nope").status_code == 404
    response = client.post("/api/rulesets/jobs-e/validate", json={"files": files("e")}, headers=ASYNC)
    done = follow(client, response.headers["location"])
    refused = client.delete(response.headers["location"])
    assert refused.status_code == 409 and done["status"] in refused.json()["error"]


def test_another_process_answers_for_a_job_and_a_dead_owner_is_reported(api_gateway):
    """Records live in the Information State: a second service (another process) reads them."""
    records = JobRecords(api_gateway.store.db)
    ours = JobService(api_gateway.engine, records, "process-a")
    try:
        job = ours.submit("validate", "jobs-f", files("f"))
        deadline = time.monotonic() + 120
        while ours.get(job["id"])["status"] not in ("succeeded", "failed") and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        ours.close()
    other = JobService(api_gateway.engine, JobRecords(api_gateway.store.db), "process-b", alive=lambda p: False)
    try:
        assert other.get(job["id"])["status"] == "succeeded"
        stuck = {**ours.get(job["id"]), "id": "stuck-1", "status": "running",
                 "updated_at": "2020-01-01T00:00:00+00:00"}
        records.write(stuck)
        lost = other.get("stuck-1")
        assert lost["status"] == "failed" and lost["error"]["kind"] == "lost"
        assert "process-a" in lost["error"]["error"]
    finally:
        other.close()


def test_queued_jobs_can_be_cancelled_and_a_full_queue_refuses(api_gateway):
    import threading

    from gateway.runtime.jobs import JobError

    gate = threading.Event()

    class SlowEngine:
        def validate(self, name, files, on_progress=None, role=None):
            gate.wait(30)
            return []

    service = JobService(SlowEngine(), JobRecords(), "process-c", max_queued=1)
    try:
        first = service.submit("validate", "x", {"a.drl": ""})
        deadline = time.monotonic() + 10
        while service.get(first["id"])["status"] != "running" and time.monotonic() < deadline:
            time.sleep(0.01)
        second = service.submit("validate", "x", {"a.drl": ""})
        with pytest.raises(JobError) as full:
            service.submit("validate", "x", {"a.drl": ""})
        assert full.value.status == 429
        asked = service.cancel(first["id"], "bob")  # running: asked to stop at its next progress report
        assert asked["status"] == "running" and asked["cancel_requested"] is True
        assert service.cancel(second["id"], "alice")["status"] == "cancelled"
    finally:
        gate.set()
        service.close()
    # it never reported progress again (past compiling): it finished as it would have
    assert service.get(first["id"])["status"] == "succeeded"
    with pytest.raises(JobError) as finished:
        service.cancel(first["id"])
    assert finished.value.status == 409


def test_a_running_build_is_cancelled_while_compiling_and_nothing_changes(client):
    """A real 400-rule deploy job, cancelled once it reports compiling: it ends ``cancelled``
    (202 when asked), nothing is deployed, and the next deploy works."""
    big = growth_rules.drl_files(400)
    response = client.put("/api/rulesets/jobs-h", json={"files": big}, headers=ASYNC)
    location = response.headers["location"]
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        job = client.get(location).json()
        if (job.get("progress") or {}).get("stage") == "compile" or job["status"] not in ("queued", "running"):
            break
        time.sleep(0.02)
    asked = client.delete(location)
    assert asked.status_code == 202 and asked.json()["cancel_requested"] is True, asked.json()
    done = follow(client, location)
    assert done["status"] == "cancelled" and done["error"]["kind"] == "cancelled", done
    assert "nothing was deployed" in done["error"]["error"]
    assert client.get("/api/rulesets/jobs-h").status_code == 404
    assert client.put("/api/rulesets/jobs-h", json={"files": files("h")}).status_code == 201


def test_a_full_job_queue_is_told_as_429_over_rest(client, api_gateway, monkeypatch):
    """The gateway's own job service and engine: one real build held while compiling, one queued
    behind it, the next refused (the queue bound lowered to 1 for this test)."""
    import uuid

    from gw_testing import hold_build

    marker = uuid.uuid4().hex[:8]  # a build no compile cache has seen
    release = hold_build(monkeypatch, api_gateway.engine, f"held {marker}")
    monkeypatch.setattr(api_gateway.jobs, "max_queued", 1)
    locations = []
    try:
        first = client.put("/api/rulesets/jobs-g", json={"files": files(marker), "comment": f"held {marker}"},
                           headers=ASYNC)
        assert first.status_code == 202
        locations.append(first.headers["location"])
        deadline = time.monotonic() + 120  # a safety limit: the build is held at its compile stage
        while (client.get(first.headers["location"]).json().get("progress") or {}).get("stage") != "compile":
            assert time.monotonic() < deadline, client.get(first.headers["location"]).json()
            time.sleep(0.02)
        queued = client.put("/api/rulesets/jobs-g", json={"files": files(marker)}, headers=ASYNC)
        assert queued.status_code == 202 and queued.json()["status"] == "queued"
        locations.append(queued.headers["location"])
        refused = client.put("/api/rulesets/jobs-g", json={"files": files(marker)}, headers=ASYNC)
        assert refused.status_code == 429 and "engine.max_queued_jobs = 1" in refused.json()["error"], refused.text
    finally:
        for location in reversed(locations):
            client.delete(location)
        release.set()
    assert [follow(client, location)["status"] for location in locations] == ["cancelled", "cancelled"]
