"""Deploying through build jobs in the workbench (real gateway, real Drools, Debian chromium): the
deploy card follows the job to the same ends the synchronous deploy had (the version live, compile
problems under the editor), the "Build jobs" card lists the rule set's jobs, and a queued build is
cancelled from either place."""

from __future__ import annotations

import threading
import time
import uuid

import pytest
from playwright.sync_api import expect

from gw_testing import hold_build
from wb_helpers import REFUSED_REQUEST, console_errors, example_facts, line_of, open_ruleset, reception_files, replace_text, said

pytestmark = pytest.mark.browser

ASYNC = {"Prefer": "respond-async"}
OLD_GREETING = "Welcome. Two seats?"
#: Rules in the "slow" build. Its slowness is the test's hold (gw_testing.hold_build keeps it at
#: its first compile report until the test has looked), not its size: a few rules show the stage
#: and done / total as well as 600 did, which then compiled for real for ~10 s quiet (173 s on a
#: loaded machine) after the release.
SLOW_RULES = 12


def generated_files(rules: int) -> dict[str, str]:
    """A rule set of ``rules`` distinct rules; a fresh token in every rule keeps the compile caches
    (in memory and under ~/.cache/printeps) from making the build quick."""
    token = uuid.uuid4().hex[:10]
    head = "package gen;\n\ndeclare Guest\n    id : String\n    n : int\nend\n\n"
    body = "".join(
        f'rule "r{i} {token}"\nwhen\n    Guest( n == {i}, id == "{token}-{i}" )\nthen\n    String unused = "{token}";  // not a plain rule: compiled to Java (slow on purpose)\nend\n\n'
        for i in range(rules))
    return {"generated.drl": head + body}


def submit(gateway, name: str, files: dict[str, str], comment: str) -> dict:
    """A deploy job submitted over REST (202)."""
    with gateway.rest() as client:
        response = client.put(f"/api/rulesets/{name}", json={"files": files, "comment": comment}, headers=ASYNC)
    assert response.status_code == 202, response.text
    return response.json()


def job_status(gateway, job_id: str) -> dict:
    with gateway.rest() as client:
        return client.get(f"/api/jobs/{job_id}").json()


def wait_for(gateway, job_id: str, statuses: tuple[str, ...], timeout_s: float = 180.0) -> dict:
    """Poll a job until its status is one of ``statuses`` (the test's safety limit, not a timing claim)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        job = job_status(gateway, job_id)
        if job["status"] in statuses:
            return job
        time.sleep(0.1)
    pytest.fail(f"job {job_id} never became {statuses}")


def open_jobs(page):
    """Open the collapsed "Build jobs" card; returns its list."""
    page.get_by_test_id("build-jobs").locator("summary").click()
    return page.get_by_test_id("jobs-list")


def test_a_deploy_is_built_as_a_job_and_its_version_goes_live(author_page, gateway, ruleset):
    page = author_page
    facts = example_facts(reception_files(), "group of two adults")
    open_ruleset(page, ruleset)
    replace_text(page, OLD_GREETING, "Built by a job")
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")
    page.get_by_label("What did you change?").fill("through a build job")
    page.get_by_test_id("deploy").click()
    expect(page.get_by_test_id("deploy-result")).to_have_text("✓ Deployed. Version 2 is now live.")
    expect(page.get_by_test_id("live-version")).to_contain_text("version 2")
    expect(page.get_by_test_id("deploy")).to_be_enabled()
    expect(page.get_by_text("Changed — not deployed yet")).to_be_hidden()
    assert "Built by a job" in said(gateway.fire(ruleset, facts))

    # The Build jobs card lists the job: kind, status, who, how long, the version it made.
    row = open_jobs(page).locator("li.job")
    expect(row).to_have_count(1)
    expect(row).to_have_attribute("data-status", "succeeded")
    expect(row).to_contain_text("✓ succeeded")
    expect(row).to_contain_text("deploy")
    expect(row).to_contain_text("version 2")
    expect(row).to_contain_text("by alice")
    expect(row).to_contain_text(" s")  # its duration
    expect(row).to_contain_text("through a build job")
    expect(row.get_by_test_id("cancel-job")).to_have_count(0)
    with gateway.rest() as client:
        jobs = client.get("/api/jobs", params={"ruleset": ruleset}).json()["jobs"]
    assert [(j["kind"], j["status"], j["author"], j["result"]["version"]["version"]) for j in jobs] == \
        [("deploy", "succeeded", "alice", 2)]
    assert console_errors(page) == []


def test_a_build_that_does_not_compile_shows_its_errors_under_the_editor(author_page, gateway, ruleset):
    page = author_page
    line = line_of(reception_files()["reception.dslr"], 'rule "Child"')
    open_ruleset(page, ruleset)
    replace_text(page, 'rule "Child"', 'rule "Child" )')
    expect(page.get_by_test_id("check-status")).to_have_text("✗ 1 problem")
    page.get_by_test_id("deploy").click()
    expect(page.get_by_test_id("deploy-result")).to_have_text(
        "Not deployed: fix the 1 problem(s) listed under the editor first. Nothing was changed.")
    problem = page.get_by_test_id("problems").locator("li.error")
    expect(problem).to_have_count(1)
    expect(problem).to_contain_text(f"reception.dslr, line {line}, column 14")
    expect(problem).to_contain_text("mismatched input ')'")
    expect(page.get_by_test_id("live-version")).to_contain_text("version 1")

    row = open_jobs(page).locator("li.job")
    expect(row).to_have_count(1)
    expect(row).to_have_attribute("data-status", "failed")
    expect(row).to_contain_text("✗ failed")
    expect(row).to_contain_text(f"reception.dslr, line {line}: mismatched input ')'")
    with gateway.rest() as client:
        assert client.get(f"/api/rulesets/{ruleset}").json()["version"] == 1
    assert console_errors(page) == []


def test_a_queued_build_is_cancelled_from_the_deploy_card_and_from_the_list(author_page, gateway, ruleset, screenshots,
                                                                            monkeypatch):
    page = author_page
    open_ruleset(page, ruleset)
    release = hold_build(monkeypatch, gateway.engine, "a slow build")
    try:
        _queued_builds_are_cancelled(page, gateway, ruleset, screenshots, release)
    finally:
        release.set()


def _queued_builds_are_cancelled(page, gateway, ruleset, screenshots, release) -> None:

    # A slow build over REST takes the (one) build slot of the gateway process...
    slow = submit(gateway, ruleset, generated_files(SLOW_RULES), "a slow build")
    wait_for(gateway, slow["id"], ("running",))

    # ...so the author's deploy waits in the queue: the card says so and offers to cancel.
    replace_text(page, OLD_GREETING, "Never deployed")
    page.get_by_test_id("deploy").click()
    progress = page.get_by_test_id("deploy-progress")
    expect(progress).to_have_attribute("data-status", "queued")
    expect(progress).to_contain_text("Waiting for another build to finish first")
    expect(page.get_by_test_id("deploy")).to_be_disabled()

    # The list shows both: hers queued, the slow one running with its stage and done / total.
    jobs = open_jobs(page)
    running = jobs.locator(f"li[data-job-id='{slow['id']}']")
    expect(running).to_have_attribute("data-status", "running")
    expect(running).to_contain_text("Compiling the rules: ", timeout=60_000)  # after reading the files
    expect(running).to_contain_text(f"/ {SLOW_RULES}")
    expect(running.locator("progress")).to_be_visible()
    expect(jobs.locator("li[data-status=queued]")).to_have_count(1)
    page.locator(".columns .right").screenshot(path=str(screenshots / "workbench-jobs.png"))

    # Cancel build: the queued job ends at once; nothing is deployed, her edit stays.
    assert job_status(gateway, slow["id"])["status"] == "running", "the slow build ended too early for this test"
    page.get_by_test_id("cancel-build").click()
    expect(page.get_by_test_id("build-cancelled")).to_have_text(
        "Not deployed: the build was cancelled by alice. Nothing was changed; your changes are still here.")
    expect(page.get_by_test_id("deploy")).to_be_enabled()
    expect(page.get_by_text("Changed — not deployed yet")).to_be_visible()
    cancelled = jobs.locator("li[data-status=cancelled]")
    expect(cancelled).to_have_count(1)
    expect(cancelled).to_contain_text("⊘ cancelled")
    expect(cancelled).to_contain_text("cancelled by alice")

    # A job someone queued over REST is cancelled from the list.
    other = submit(gateway, ruleset, reception_files(), "queued over REST")
    queued = jobs.locator(f"li[data-job-id='{other['id']}']")
    expect(queued).to_have_attribute("data-status", "queued")
    assert job_status(gateway, slow["id"])["status"] == "running", "the slow build ended too early for this test"
    queued.get_by_test_id("cancel-job").click()
    expect(queued).to_have_attribute("data-status", "cancelled")
    assert job_status(gateway, other["id"])["status"] == "cancelled"

    # The slow build ends as version 2; the list follows it there.
    release.set()
    wait_for(gateway, slow["id"], ("succeeded", "failed"))
    expect(running).to_have_attribute("data-status", "succeeded")
    expect(running).to_contain_text("version 2")
    expect(jobs.locator("li.job")).to_have_count(3)
    assert console_errors(page) == []


STAGE_WORDS = {"compile": "Compiling the rules", "scenarios": "Running the test scenarios"}


@pytest.mark.parametrize("held_at", ["compile", "scenarios"])
def test_a_running_build_shows_its_stage_and_cancel_stops_it_or_is_explained(author_page, gateway, ruleset,
                                                                              monkeypatch, held_at):
    """The deploy card while a real build runs, and "Cancel build" on it, all against the real
    gateway: it answers 202 with ``cancel_requested``. Still compiling, the build then stops and
    nothing is deployed; past compiling (its test scenarios) it finishes and the card says why.
    The test holds the build at that stage until it has looked (so its steps never race the
    build's real pace); the browser sees only what the gateway answers."""
    page = author_page
    comment = f"held at {held_at} {uuid.uuid4().hex[:8]}"
    release = hold_build(monkeypatch, gateway.engine, comment, stage=held_at)
    try:
        open_ruleset(page, ruleset)
        replace_text(page, OLD_GREETING, f"Deployed after all {uuid.uuid4().hex[:8]}")  # no compile cache hit
        page.get_by_label("What did you change?").fill(comment)
        page.get_by_test_id("deploy").click()
        progress = page.get_by_test_id("deploy-progress")
        expect(progress).to_have_attribute("data-status", "running")
        expect(page.get_by_test_id("deploy-stage")).to_contain_text(STAGE_WORDS[held_at], timeout=60_000)

        page.get_by_test_id("cancel-build").click()
        expect(page.get_by_test_id("cancel-note")).to_contain_text("Cancelling: the build stops at its next step")
        expect(page.get_by_test_id("cancel-build")).to_have_text("Cancelling…")
        with gateway.rest() as client:
            jobs = client.get("/api/jobs", params={"ruleset": ruleset}).json()["jobs"]
        held = [j for j in jobs if j["comment"] == comment]
        assert [(j["status"], j["cancel_requested"], j["progress"]["stage"]) for j in held] == \
            [("running", True, held_at)], held
    finally:
        release.set()
    if held_at == "compile":
        cancelled = page.get_by_test_id("build-cancelled")
        expect(cancelled).to_contain_text("Not deployed: the build was cancelled by alice while compile")
        expect(cancelled).to_contain_text("Nothing was changed; your changes are still here.")
        expect(page.get_by_test_id("live-version")).to_contain_text("version 1")
        assert wait_for(gateway, held[0]["id"], ("cancelled",))["status"] == "cancelled"
    else:
        expect(page.get_by_test_id("deploy-result")).to_contain_text("✓ Deployed. Version 2 is now live.")
        expect(page.get_by_test_id("deploy-result")).to_contain_text("The build was too far along to cancel, so it finished.")
        expect(page.get_by_test_id("live-version")).to_contain_text("version 2")
    assert console_errors(page) == []
