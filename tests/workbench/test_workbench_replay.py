"""What would change, and why, in the workbench (real gateway, real Drools, Debian chromium): the
draft replayed over the rule set's recorded decisions before Deploy, a deploy after a replay that
changed decisions asks for a comment that says so, and a decision explained rule by rule with its
trace as a timeline. Screenshots go to docs/img with PRINTEPS_SCREENSHOTS=1."""

from __future__ import annotations

import pytest
from playwright.sync_api import expect

from wb_helpers import AUTHOR_TOKEN, REFUSED_REQUEST, console_errors, example_facts, open_ruleset, reception_files, replace_text

pytestmark = pytest.mark.browser


def record(gateway, name: str, example: str, request_id: str) -> dict:
    with gateway.rest(AUTHOR_TOKEN) as client:
        response = client.post(f"/api/rulesets/{name}/fire", json={"facts": example_facts(reception_files(), example)},
                               headers={"X-Request-ID": request_id})
    assert response.status_code == 200, response.text
    return response.json()


def test_what_would_change_before_deploy(gateway, ruleset, author_page, screenshots):
    page = author_page
    for k, example in enumerate(["group of two adults", "group of two adults", "couple", "single guest"]):
        record(gateway, ruleset, example, f"{ruleset}-{k}")
    open_ruleset(page, ruleset)
    replace_text(page, "Welcome. Two seats?", "Hello, you two!")
    page.get_by_test_id("replay").click()
    expect(page.get_by_test_id("replay-summary")).to_have_text("2 of 4 recent decisions would change.", timeout=120_000)
    changes = page.get_by_test_id("replay-change")
    expect(changes).to_have_count(2)
    expect(changes.first).to_contain_text("Welcome. Two seats?")
    expect(changes.first).to_contain_text("Hello, you two!")
    assert changes.first.locator("a").get_attribute("href").startswith("#/decisions/")
    expect(page.get_by_test_id("replay-rules")).to_contain_text("Greet a pair")
    page.get_by_test_id("replay-result").screenshot(path=str(screenshots / "workbench-what-would-change.png"))

    page.get_by_test_id("deploy").click()
    expect(page.get_by_test_id("replay-comment-needed")).to_contain_text("would change 2 recent decisions")
    with gateway.rest() as client:
        assert client.get(f"/api/rulesets/{ruleset}").json()["version"] == 1  # nothing was deployed
    page.get_by_label("What did you change?").fill("Friendlier greeting for pairs")
    page.get_by_test_id("deploy").click()
    expect(page.get_by_test_id("deploy-result")).to_contain_text("Version 2 is now live", timeout=120_000)
    with gateway.rest() as client:
        history = client.get(f"/api/rulesets/{ruleset}/history").json()
    assert history[-1]["comment"] == "Friendlier greeting for pairs [replay: 2 of 4 recent decisions change]"
    assert console_errors(page, REFUSED_REQUEST) == []


def test_a_decision_is_explained_rule_by_rule_with_its_trace(gateway, ruleset, author_page, screenshots):
    page = author_page
    fired = record(gateway, ruleset, "single guest", f"{ruleset}-why")
    page.goto(f"/workbench#/decisions/{fired['decision_id']}")
    page.get_by_test_id("explain-button").click()
    explain = page.get_by_test_id("explain")
    expect(explain).to_contain_text("rules fired.", timeout=120_000)
    expect(explain.locator("li.fired[data-rule='Greet a single guest']")).to_contain_text("✓ Greet a single guest")
    pair = explain.locator("li.not-fired[data-rule='Greet a pair']")
    expect(pair).to_contain_text("did not fire:")
    expect(pair.locator("code.written")).not_to_be_empty()
    page.get_by_test_id("trace-button").click()
    trace = page.get_by_test_id("trace")
    expect(trace).to_contain_text("1 records")
    expect(trace.locator("li")).to_contain_text("Decision")
    page.locator(".why-card").screenshot(path=str(screenshots / "workbench-explain.png"))
    assert console_errors(page, REFUSED_REQUEST) == []
