"""The issue's end-to-end story in a real browser against the real gateway: open a rule set, make a
syntax error and see it marked at its line, fix it, try facts and see the greeting, deploy, see the
new version fire through the REST API, roll back."""

from __future__ import annotations

import pytest
from playwright.sync_api import expect

from wb_helpers import reception_files
from wb_helpers import EDITOR, example_facts, line_of, open_ruleset, replace_text, said, try_example

pytestmark = [pytest.mark.browser, pytest.mark.slow]  # a browser story: make test runs it, make test-fast not

OLD_GREETING = "Welcome. Two seats?"
NEW_GREETING = "Welcome to our teahouse, you two!"


def test_edit_check_try_deploy_fire_rollback(author_page, gateway, ruleset, screenshots):
    page = author_page
    files = reception_files()
    facts = example_facts(files, "group of two adults")
    assert OLD_GREETING in said(gateway.fire(ruleset, facts))

    open_ruleset(page, ruleset)
    # The sentences (.dslr) are what a non-programmer meets first.
    expect(page.locator(".tab[aria-selected=true]")).to_have_attribute("data-file", "reception.dslr")
    expect(page.get_by_test_id("live-version")).to_contain_text("version 1")

    # A syntax error is marked at its line and column, inline and in the list.
    line = line_of(files["reception.dslr"], 'rule "Child"')
    replace_text(page, 'rule "Child"', 'rule "Child" )')
    expect(page.get_by_test_id("check-status")).to_have_text("✗ 1 problem")
    problem = page.get_by_test_id("problems").locator("li.error")
    expect(problem).to_have_count(1)
    expect(problem).to_contain_text(f"reception.dslr, line {line}, column 14")
    expect(problem).to_contain_text("mismatched input ')'")
    problem.locator("button").click()  # jumps to the place
    marked = page.locator(f"{EDITOR} .cm-activeLine .cm-lintRange-error")
    expect(marked).to_have_text(")")
    expect(page.locator(f"{EDITOR} .cm-activeLine")).to_have_text('rule "Child" )')
    expect(page.locator(".tab[data-file='reception.dslr'] .tab-count")).to_have_text("1")
    page.screenshot(path=str(screenshots / "workbench-check.png"))

    # Fixing it clears the marks.
    page.keyboard.press("End")
    page.keyboard.press("Backspace")
    page.keyboard.press("Backspace")
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")
    expect(page.locator(f"{EDITOR} .cm-lintRange-error")).to_have_count(0)

    # Change what Pepper says and try it on a ready example, undeployed.
    replace_text(page, OLD_GREETING, NEW_GREETING)
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")
    try_example(page, "group of two adults")
    result = page.get_by_test_id("try-result")
    expect(result.get_by_test_id("actions")).to_contain_text(f"pepper says {NEW_GREETING}")
    expect(result.get_by_test_id("fired")).to_contain_text("Greet a pair")
    result.scroll_into_view_if_needed()
    page.screenshot(path=str(screenshots / "workbench-try.png"))
    assert OLD_GREETING in said(gateway.fire(ruleset, facts)), "trying must not deploy"

    # Deploy with a comment; the REST API now fires the new version.
    page.get_by_label("What did you change?").fill("Warmer greeting for pairs")
    page.get_by_test_id("deploy").click()
    expect(page.get_by_test_id("deploy-result")).to_contain_text("Version 2 is now live")
    expect(page.get_by_test_id("live-version")).to_contain_text("version 2")
    fired = gateway.fire(ruleset, facts)
    assert fired["version"] == 2
    assert NEW_GREETING in said(fired)

    # History: both versions with author and comment, the difference, then roll back.
    page.get_by_role("link", name="History").click()
    versions = page.get_by_test_id("versions")
    expect(versions.locator("tr[data-version='2']")).to_contain_text("alice")
    expect(versions.locator("tr[data-version='2']")).to_contain_text("Warmer greeting for pairs")
    expect(versions.locator("tr[data-version='2']")).to_contain_text("Live now")
    diff = page.get_by_test_id("diff")
    expect(diff).to_contain_text("reception.dslr")
    expect(diff.locator(".cm-changedLine").first).to_be_visible()
    page.screenshot(path=str(screenshots / "workbench-history.png"))
    versions.locator("tr[data-version='1']").get_by_role("button", name="Roll back to this version").click()
    page.get_by_role("button", name="Yes, roll back").click()
    expect(page.locator(".flash")).to_contain_text("Rolled back")
    expect(page.locator(".flash")).to_contain_text("live again")
    expect(versions.locator("tr.live-row")).to_contain_text("Live now")
    fired = gateway.fire(ruleset, facts)
    assert OLD_GREETING in said(fired) and NEW_GREETING not in said(fired)

    # Recent decisions show the fires, with the rules and what Pepper said.
    page.get_by_role("link", name="Decisions", exact=True).click()
    decisions = page.get_by_test_id("decisions")
    expect(decisions).to_contain_text(NEW_GREETING)
    expect(decisions).to_contain_text("Greet a pair")
    page.screenshot(path=str(screenshots / "workbench-decisions.png"))


def test_dsl_preview_and_unmatched_sentence(author_page, ruleset, screenshots):
    page = author_page
    files = reception_files()
    open_ruleset(page, ruleset)
    page.get_by_text("Show the DRL it becomes").click()
    preview = page.get_by_test_id("preview")
    preview.evaluate("el => el.scrollIntoView({block: 'start'})")  # below the rule list: the editor draws what is in view
    # The editor column fits the window (issue 31), so the preview shows ~15 lines: open the first
    # rule from the list; the preview follows the editor to it.
    page.get_by_test_id("rule-list").locator(".rule-item[data-rule='Infant']").click()
    expect(preview).to_contain_text("Customer(category == null")
    # Editing a sentence updates the DRL beside it, scrolled to the same place.
    replace_text(page, OLD_GREETING, "Hello, you two!")
    expect(preview).to_contain_text('actions.say("pepper", "Hello, you two!")')
    page.screenshot(path=str(screenshots / "workbench-preview.png"))

    line = line_of(files["reception.dslr"], "- aged between 4 and 12")
    replace_text(page, "- aged between 4 and 12", "- aged from 4 to 12")
    problem = page.get_by_test_id("problems").locator("li")
    expect(problem).to_have_count(1)
    expect(problem).to_contain_text(f"reception.dslr, line {line}, column 5")
    expect(problem).to_contain_text("no DSL sentence matches")
    expect(page.locator(f"{EDITOR} .cm-lintRange-error")).to_have_text("- aged from 4 to 12")
    expect(preview).to_contain_text("Showing the last good expansion")
    expect(preview).to_contain_text("age >= 4, age <= 12")  # the rule being edited, as last expanded

    # The sentence dictionary is a tab of its own, with its entries highlighted.
    page.locator(".tab[data-file='reception.dsl']").click()
    expect(page.locator(EDITOR)).to_contain_text("[condition][]There is a customer without a type")
    expect(preview).to_contain_text("is not a .dslr file")
