"""The one shell: every section in one navigation, deep links by path, keyboard and tablet width."""

from __future__ import annotations

import os
import re

from playwright.sync_api import expect

from wb_helpers import AUTHOR_TOKEN, new_page

SECTIONS = ["Rules", "Workflows", "Knowledge", "Streams", "Live", "Dialogue", "Decisions", "History"]


def test_one_navigation_reaches_every_section(author_page):
    page = author_page
    page.goto("/")
    expect(page).to_have_url(re.compile(r"/workbench"))
    nav = page.get_by_role("navigation", name="Sections")
    for label in SECTIONS:
        nav.get_by_role("link", name=label, exact=True).click()
        expect(nav.get_by_role("link", name=label, exact=True)).to_have_attribute("aria-current", "page")
        expect(page.locator("main h1").first).to_be_visible()


def test_a_path_deep_link_opens_its_item(author_page):
    page = author_page
    page.goto("/workbench/rules/reception")
    expect(page).to_have_url(re.compile(r"/workbench#/rules/reception$"))
    expect(page.locator("[data-ruleset=reception]")).to_be_visible()
    page.goto("/workflows")
    expect(page).to_have_url(re.compile(r"/workbench#/workflows(/\w+)?$"))  # the view opens the first one


def test_sections_are_reachable_by_keyboard(author_page):
    page = author_page
    page.goto("/workbench#/rules/reception")
    expect(page.locator("[data-ruleset=reception]")).to_be_visible()
    page.get_by_role("navigation", name="Sections").get_by_role("link", name="Decisions", exact=True).focus()
    page.keyboard.press("Enter")
    expect(page).to_have_url(re.compile(r"#/decisions$"))


def test_tablet_width_keeps_everything_on_screen(browser, gateway):
    page = new_page(browser, gateway, AUTHOR_TOKEN)
    page.set_viewport_size({"width": 768, "height": 1024})
    page.goto("/workbench#/rules/reception")
    expect(page.locator("[data-testid=check-status]")).to_have_text("✓ No problems")
    width = page.evaluate("document.documentElement.scrollWidth")
    assert width <= 768, f"the page scrolls sideways at tablet width ({width} px)"
    page.context.close()
    assert page.js_errors == []


def test_an_author_creates_a_rule_set_in_the_browser(author_page, gateway):
    page = author_page
    name = f"created-{os.getpid()}"
    page.goto("/workbench#/rules/reception")
    expect(page.locator("[data-ruleset=reception]")).to_be_visible()
    page.get_by_role("button", name="+ New rule set").click()
    field = page.get_by_test_id("new-ruleset-name")
    field.fill("my rules")
    expect(page.get_by_test_id("new-ruleset-result")).to_contain_text("only letters, digits")
    field.fill("reception")
    expect(page.get_by_test_id("new-ruleset-result")).to_contain_text("already a rule set named")
    page.get_by_test_id("create-ruleset").click()
    expect(page.get_by_test_id("new-ruleset-result")).to_contain_text("already a rule set named")
    field.fill(name)
    page.get_by_test_id("create-ruleset").click()
    expect(page).to_have_url(re.compile(rf"#/rules/{name}$"))
    expect(page.locator("section.ruleset h1")).to_have_text(name)
    expect(page.locator("[data-testid=check-status]")).to_have_text("✓ No problems")
    expect(page.locator(f"[data-ruleset='{name}']")).to_be_visible()
    assert gateway.fire(name, [])["actions"] == []


def test_a_view_still_loading_does_not_pull_the_user_back(author_page):
    """Workflows opens its first workflow once the list has come. A user who has clicked on to
    Knowledge by then stays there: the late list neither moves the address nor paints the sidebar
    or the page (it did: the one-navigation test above failed when the list came late)."""
    page = author_page
    page.goto("/workbench#/rules/reception")
    expect(page.locator("[data-ruleset=reception]")).to_be_visible()
    held = []
    page.route(re.compile(r"/api/workflows$"), lambda route: held.append(route))
    nav = page.get_by_role("navigation", name="Sections")
    nav.get_by_role("link", name="Workflows", exact=True).click()
    page.wait_for_function("() => location.hash === '#/workflows'")
    nav.get_by_role("link", name="Knowledge", exact=True).click()
    expect(page.locator("#sidebar-title")).to_have_text("Knowledge")
    heading = page.locator("main h1").first.inner_text()
    assert len(held) == 1, "the workflow list was not asked for while Workflows was open"
    with page.expect_response(re.compile(r"/api/workflows$")) as late:
        held[0].continue_()
    late.value.finished()
    page.evaluate("() => new Promise((done) => setTimeout(() => setTimeout(done)))")  # the late view's turn
    assert page.evaluate("location.hash") == "#/knowledge"
    assert page.locator("#sidebar-title").text_content() == "Knowledge"
    assert page.locator("main h1").first.inner_text() == heading
    expect(nav.get_by_role("link", name="Knowledge", exact=True)).to_have_attribute("aria-current", "page")
