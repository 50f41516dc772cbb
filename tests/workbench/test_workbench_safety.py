"""Roles, conflicts and bad input in the workbench: nothing is lost, every error says what and where."""

from __future__ import annotations

import pytest
from playwright.sync_api import expect

from wb_helpers import CALLER_TOKEN, OTHER_AUTHOR_TOKEN, new_page, reception_files
from wb_helpers import EDITOR, open_ruleset, replace_text, said, example_facts

pytestmark = pytest.mark.browser


def test_two_authors_deploying_the_later_is_told_and_keeps_edits(author_page, gateway, ruleset):
    page = author_page
    open_ruleset(page, ruleset)
    replace_text(page, "Welcome. Two seats?", "Alice's greeting")
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")

    # Bob deploys version 2 from the REST API while Alice is still editing version 1.
    files = reception_files()
    files["reception.dslr"] = files["reception.dslr"].replace("Welcome. Two seats?", "Bob's greeting", 1)
    assert gateway.deploy(ruleset, files, "bob's change", base_version=1, token=OTHER_AUTHOR_TOKEN).status_code == 201

    page.get_by_test_id("deploy").click()
    conflict = page.get_by_test_id("conflict")
    expect(conflict).to_contain_text("someone else deployed version 2")
    expect(conflict).to_contain_text("nothing was lost")
    expect(page.locator(EDITOR)).to_contain_text("Alice's greeting")
    expect(conflict.get_by_role("link", name="See what changed in version 2")).to_have_attribute(
        "href", f"#/history/{ruleset}?from=1&to=2")
    assert "Bob's greeting" in said(gateway.fire(ruleset, example_facts(files, "group of two adults")))

    # Her edits survive a reload (kept as a draft), with a note that version 2 came in between.
    page.reload()
    expect(page.locator(".banners")).to_contain_text("You started from version 1; version 2 has been deployed since")
    page.get_by_role("button", name="group of two adults", exact=True).click()
    page.get_by_test_id("try").click()
    expect(page.get_by_test_id("actions")).to_contain_text("pepper says Alice's greeting")

    # She decides to deploy over Bob's version: it is still in the history.
    page.get_by_test_id("deploy").click()
    page.get_by_role("button", name="Deploy mine anyway").click()
    expect(page.get_by_test_id("deploy-result")).to_contain_text("Version 3 is now live")
    with gateway.rest() as client:
        versions = client.get(f"/api/rulesets/{ruleset}/versions").json()
    assert [(v["version"], v["author"]) for v in versions][-2:] == [(2, "bob"), (3, "alice")]


def test_caller_token_sees_read_only_views(browser, gateway):
    page = new_page(browser, gateway, CALLER_TOKEN)
    try:
        page.goto("/workbench#/rules/reception")
        expect(page.get_by_test_id("user")).to_contain_text("carol (caller)")
        expect(page.get_by_text("you can read and try the rules, but not change or deploy them")).to_be_visible()
        expect(page.locator(EDITOR)).to_have_attribute("contenteditable", "false")
        expect(page.get_by_test_id("deploy")).to_have_count(0)
        # Trying is reading: allowed.
        page.get_by_role("button", name="group of two adults", exact=True).click()
        page.get_by_test_id("try").click()
        expect(page.get_by_test_id("actions")).to_contain_text("pepper says Welcome. Two seats?")
        page.get_by_role("link", name="History").click()
        expect(page.get_by_test_id("versions")).to_be_visible()
        expect(page.get_by_role("button", name="Roll back to this version")).to_have_count(0)
        assert page.js_errors == []
    finally:
        page.context.close()


def test_sign_in_with_a_token(browser, gateway):
    page = new_page(browser, gateway, None)
    try:
        page.goto("/workbench")
        expect(page.get_by_role("heading", name="Sign in")).to_be_visible()
        page.get_by_label("Access token").fill("not-a-token")
        page.get_by_role("button", name="Sign in").click()
        expect(page.get_by_role("alert")).to_contain_text("This token was not accepted")
        page.get_by_label("Access token").fill(OTHER_AUTHOR_TOKEN)
        page.get_by_role("button", name="Sign in").click()
        expect(page.get_by_test_id("user")).to_contain_text("bob (author)")
        expect(page.get_by_test_id("rulesets")).to_contain_text("reception")
        expect(page.get_by_test_id("deploy")).to_be_visible()
        assert page.js_errors == []
    finally:
        page.context.close()


@pytest.mark.parametrize("bad_name", ["../etc", "my rules", "a/../../b"])
def test_bad_rule_set_names_get_a_clear_error(author_page, bad_name):
    page = author_page
    page.goto(f"/workbench#/rules/{bad_name}")
    alert = page.get_by_role("alert")
    expect(alert).to_contain_text(f"Cannot open the rule set “{bad_name}”")


def test_binary_paste_is_marked_and_refused(author_page, gateway, ruleset):
    page = author_page
    open_ruleset(page, ruleset)
    page.locator(EDITOR).click()
    page.keyboard.press("Control+Home")
    page.keyboard.insert_text("\x00\x01\x02PK\x03\x04\n")
    expect(page.get_by_test_id("check-status")).to_contain_text("✗")
    problems = page.get_by_test_id("problems")
    expect(problems).to_contain_text("reception.dslr, line 1, column 1")
    page.get_by_label("What did you change?").fill("binary")
    page.get_by_test_id("deploy").click()
    expect(page.get_by_test_id("deploy-result")).to_contain_text("Not deployed")
    with gateway.rest() as client:
        assert client.get(f"/api/rulesets/{ruleset}").json()["version"] == 1


def test_huge_file_is_refused_with_its_name(author_page, gateway, ruleset):
    page = author_page
    open_ruleset(page, ruleset)
    page.locator(EDITOR).click()
    page.keyboard.press("Control+End")
    page.keyboard.insert_text("\n// " + "x" * 1_100_000 + "\n")
    problems = page.get_by_test_id("problems")
    expect(problems).to_contain_text("reception.dslr")
    expect(problems).to_contain_text("file too large")
    page.get_by_test_id("deploy").click()
    expect(page.get_by_test_id("deploy-result")).to_contain_text("Not deployed")
    with gateway.rest() as client:
        assert client.get(f"/api/rulesets/{ruleset}").json()["version"] == 1
