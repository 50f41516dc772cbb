"""The owner's first hour (issue 31), in the real workbench on a real gateway: the rules as a list
of what they do with a search, "Update the tests too" when a changed sentence blocks the deploy,
and a layout whose top bar, palette, run panel, Deploy and Try stay usable at 1280×800 and at
tablet width (820×1180)."""

from __future__ import annotations

import os

import httpx
from playwright.sync_api import expect

from wb_helpers import AUTHOR_TOKEN, EDITOR, RECEPTION, folder_files, new_page, open_ruleset, replace_text

OLD, NEW = "Welcome. Two seats?", "Welcome! A table for two?"
TESTS = "tests/reception.yaml"
_count = iter(range(1, 10_000))


def deploy_forced(gateway, files: dict[str, str], stem: str) -> str:
    """A copy of a rule set under a name of its own (forced: its scenarios may be red on purpose)."""
    name = f"{stem}-{os.getpid()}-{next(_count)}"
    with gateway.rest() as client:
        r = client.put(f"/api/rulesets/{name}", json={"files": files, "comment": "copy for a test", "force": True})
    assert r.status_code == 201, r.text
    return name


def said(result: dict) -> list[str]:
    return [a["params"]["text"] for a in result["actions"] if a["module"] == "say"]


PAIR = [{"type": "Entrance", "id": "entrance", "number_of_customers": 2},
        {"type": "Customer", "id": "c1", "entrance": "entrance", "age": 30, "gender": "female"},
        {"type": "Customer", "id": "c2", "entrance": "entrance", "age": 31, "gender": "female"},
        {"type": "Robot", "id": "pepper", "position": "entrance"}]


def test_the_rules_as_a_list_a_search_and_a_jump(author_page, gateway, screenshots):
    page = author_page
    page.set_viewport_size({"width": 1280, "height": 800})
    open_ruleset(page, "reception")
    rules = page.get_by_test_id("rule-list")
    expect(rules.locator(".rule-item")).to_have_count(32)
    pair = rules.locator(".rule-item[data-rule='Greet a pair']")
    expect(pair).to_contain_text(f'Pepper says "{OLD}"')
    expect(page.get_by_test_id("used-by")).to_contain_text("CustomerDetectionQuery")
    expect(page.get_by_test_id("used-by")).to_contain_text("fire_business_rules")

    page.get_by_test_id("rule-search").fill("Two seats")
    expect(rules.locator(".rule-item")).to_have_count(3)
    expect(rules).to_contain_text("Greet a pair")
    expect(rules).not_to_contain_text("Infant")
    expect(page.locator(f"{EDITOR} .cm-find-match").first).to_be_visible()  # the words marked in the editor
    page.screenshot(path=str(screenshots / "workbench-rule-list.png"))

    page.get_by_test_id("rule-search").fill("")
    expect(rules.locator(".rule-item")).to_have_count(32)
    rules.locator(".rule-item[data-rule='Greet a large group']").click()
    line = page.locator(f"{EDITOR} .cm-activeLine")
    expect(line).to_have_text('rule "Greet a large group"')
    expect(line).to_be_in_viewport()

    page.get_by_test_id("rule-search").fill("no such words anywhere")
    expect(rules).to_contain_text("No rule says that.")


def test_the_list_follows_the_edit_and_a_copy_is_fed_by_nothing(author_page, ruleset):
    page = author_page
    open_ruleset(page, ruleset)
    expect(page.get_by_test_id("used-by")).to_contain_text("Nothing feeds this rule set yet")
    replace_text(page, OLD, NEW)
    page.get_by_test_id("rule-search").fill("table for two?")
    expect(page.get_by_test_id("rule-list").locator(".rule-item")).to_have_count(1)
    expect(page.get_by_test_id("rule-list")).to_contain_text("Greet a pair")


def test_a_new_rule_from_grouped_menus_brings_the_party_and_is_named_after_what_it_does(author_page, ruleset):
    page = author_page
    open_ruleset(page, ruleset)
    page.get_by_role("button", name="+ New rule", exact=True).click()
    conditions = page.get_by_label("Add a condition")
    assert conditions.locator("optgroup").evaluate_all("gs => gs.map((g) => g.label)") == [
        "Most used", "Customers and their type", "The party at the entrance and its group",
        "Greeting the party: what Pepper says and does", "Narrowing the sentence above"]
    assert conditions.locator("optgroup[label='Most used'] option").all_inner_texts() == [
        "There is a party at the entrance", "Pepper is at the entrance", "Everyone in the party has a type"]
    conditions.select_option(label="Everyone in the party has a type")
    when = page.get_by_role("list", name="When")
    expect(when.get_by_role("listitem")).to_have_count(2)
    assert when.get_by_role("listitem").all_inner_texts()[0].startswith("There is a party at the entrance")
    expect(page.get_by_role("region", name="A new rule")).to_contain_text(
        "Added “There is a party at the entrance” under When: “Everyone in the party has a type” is about it.")

    page.get_by_label("Add an action").select_option(label='Pepper says "…"')
    page.get_by_role("button", name="Add the rule", exact=True).click()  # the blank is still empty
    expect(page.get_by_role("alert")).to_contain_text("“Pepper says \"…\"”: fill in the text.")
    page.get_by_label('text in: Pepper says "…"').fill("A blanket?")
    page.get_by_role("button", name="Add the rule", exact=True).click()
    expect(page.get_by_role("status").filter(has_text="✓ Rule “Pepper says “A blanket?”” added")).to_be_visible()
    expect(page.get_by_test_id("rule-list").locator(".rule-item[data-rule='Pepper says “A blanket?”']")).to_be_visible()
    expect(page.locator(EDITOR)).to_contain_text('rule "Pepper says “A blanket?”"')
    # the compiler takes the rule as written (a loaded machine compiles slowly)
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems", timeout=120_000)


def test_update_the_tests_too_then_deploy(author_page, gateway, screenshots):
    page = author_page
    files = folder_files(RECEPTION)
    name = deploy_forced(gateway, files, "owner-update")
    open_ruleset(page, name)
    page.get_by_test_id("run-tests").click()
    expect(page.get_by_test_id("tests-summary")).to_have_text("✓ All 24 scenarios pass")

    replace_text(page, f'Pepper says "{OLD}"', f'Pepper says "{NEW}"')
    expect(page.get_by_test_id("tests-stale")).to_be_visible()  # the results no longer match the text
    page.get_by_test_id("deploy").click()
    refused = page.get_by_test_id("red-scenarios")
    expect(refused).to_contain_text("Not deployed: 3 test scenarios fail")
    offer = page.get_by_test_id("tests-update")
    expect(offer.locator("li")).to_have_count(3)
    expect(offer).to_contain_text(f"“{OLD}” → “{NEW}”")
    expect(page.get_by_test_id("tests-kept")).to_have_count(0)
    refused.scroll_into_view_if_needed()
    page.screenshot(path=str(screenshots / "workbench-update-tests.png"))

    page.get_by_test_id("update-tests").click()
    expect(page.get_by_test_id("deploy-result")).to_contain_text("Version 2 is now live")
    assert said(gateway.fire(name, PAIR)) == [NEW]
    with gateway.rest() as client:
        stored = client.get(f"/api/rulesets/{name}").json()["files"][TESTS]
    assert stored.count(f'"{NEW}"') == 3 and f'"{OLD}"' not in stored
    assert stored.split("\n")[:9] == files[TESTS].split("\n")[:9]  # the header comments kept
    assert "ordered: true                # Pepper comes to the entrance before she greets" in stored


def test_a_scenario_red_for_another_reason_is_never_rewritten(author_page, gateway):
    page = author_page
    files = folder_files(RECEPTION)
    text = files[TESTS]
    teen = text.index("- name: teenage boy and girl")
    end = text.index("- name:", teen + 5)
    files[TESTS] = text[:teen] + text[teen:end].replace("location: table for two", "location: table for three") + text[end:]
    name = deploy_forced(gateway, files, "owner-kept")
    open_ruleset(page, name)

    replace_text(page, f'Pepper says "{OLD}"', f'Pepper says "{NEW}"')
    page.get_by_test_id("deploy").click()
    expect(page.get_by_test_id("red-scenarios")).to_contain_text("Not deployed: 3 test scenarios fail")
    expect(page.get_by_test_id("tests-update").locator("li")).to_have_count(2)
    expect(page.get_by_test_id("tests-kept")).to_contain_text("teenage boy and girl are a pair, not a couple")
    page.get_by_test_id("update-tests").click()

    # The two pair scenarios now pass; the teenage one stays red, listed first, scrolled into view.
    summary = page.get_by_test_id("tests-summary")
    expect(summary).to_have_text("✗ 1 of 24 scenarios fail")
    first = page.get_by_test_id("tests").locator("> li").first
    expect(first).to_have_attribute("data-status", "failed")
    expect(first).to_contain_text("teenage boy and girl")
    expect(summary).to_be_in_viewport()
    with gateway.rest() as client:
        versions = client.get(f"/api/rulesets/{name}/versions").json()
    assert [v["version"] for v in versions] == [1]  # nothing deployed


def test_update_over_rest_needs_a_token(gateway):
    with httpx.Client(base_url=gateway.base_url, timeout=30) as client:
        r = client.post("/api/rulesets/reception/tests/update", json={"files": {"a.drl": ""}})
    assert r.status_code == 401


def boxes_intersect(a: dict, b: dict) -> bool:
    return not (a["x"] + a["width"] <= b["x"] or b["x"] + b["width"] <= a["x"]
                or a["y"] + a["height"] <= b["y"] or b["y"] + b["height"] <= a["y"])


def test_layout_at_desktop_and_tablet_width(browser, gateway, screenshots):
    for width, height in ((1280, 800), (820, 1180)):
        page = new_page(browser, gateway, AUTHOR_TOKEN)
        try:
            page.set_viewport_size({"width": width, "height": height})
            page.goto("/workbench#/workflows/greeting")
            palette, run = page.locator(".wf-side"), page.locator(".wf-run")
            expect(palette).to_be_visible()
            expect(run).to_be_visible()
            for scroll in (0, 400, 800, 5000):
                page.evaluate(f"window.scrollTo(0, {scroll})")
                page.wait_for_function(f"window.scrollY >= Math.min({scroll}, document.documentElement.scrollHeight - innerHeight) - 1")
                assert not boxes_intersect(palette.bounding_box(), run.bounding_box()), (width, scroll)
                assert page.locator("header.top").bounding_box()["y"] == 0, (width, scroll)  # the top bar stays put

            open_ruleset(page, "reception")
            page.evaluate("window.scrollTo(0, document.documentElement.scrollHeight)")
            expect(page.locator("header.top")).to_be_in_viewport()
            if width < 900:  # tablet: the reach bar brings Deploy and Try
                expect(page.get_by_test_id("reach-deploy")).to_be_in_viewport()
                page.evaluate("window.scrollTo(0, 0)")
                page.get_by_test_id("reach-try").click()
                expect(page.get_by_test_id("try")).to_be_in_viewport()
                page.get_by_test_id("reach-deploy").click()
                expect(page.get_by_test_id("deploy")).to_be_in_viewport()
                page.screenshot(path=str(screenshots / "workbench-tablet.png"))
            else:  # desktop: the side column stays beside the editor
                expect(page.get_by_test_id("deploy")).to_be_in_viewport()
            assert page.evaluate("document.documentElement.scrollWidth <= innerWidth")  # nothing scrolls sideways
            assert page.js_errors == []
        finally:
            page.context.close()


LINES_JS = """e => { const r = document.createRange(); r.selectNodeContents(e);
    return new Set([...r.getClientRects()].map((x) => Math.round(x.top))).size; }"""
#: The character before each line break of an element's text (a word boundary: "-" in a name).
BREAKS_JS = """e => { const text = e.firstChild; const out = []; let top = null;
    for (let i = 0; i < text.length; i++) { const r = document.createRange(); r.setStart(text, i); r.setEnd(text, i + 1);
      const t = Math.round(r.getBoundingClientRect().top); if (top !== null && t > top) out.push(text.data[i - 1]); top = t; }
    return out; }"""


def test_long_names_wrap_at_word_boundaries_and_the_palette_shows_it_scrolls(browser, gateway):
    name = deploy_forced(gateway, folder_files(RECEPTION), "reception-for-the-long-weekend-tea-ceremony-families")
    for width, height in ((1280, 800), (820, 1180)):
        page = new_page(browser, gateway, AUTHOR_TOKEN)
        try:
            page.set_viewport_size({"width": width, "height": height})
            open_ruleset(page, name)
            # the narrow column wraps the name: in the list of rule sets at desktop width, the title at tablet width
            wrapped = page.locator(f"[data-ruleset='{name}'] .name") if width > 900 \
                else page.get_by_role("heading", name=name, exact=True)
            assert wrapped.evaluate(LINES_JS) >= 2, width
            assert set(wrapped.evaluate(BREAKS_JS)) == {"-"}, width  # each line ends at a word boundary
            assert wrapped.evaluate("e => e.scrollWidth <= e.clientWidth"), width
            assert page.evaluate("document.documentElement.scrollWidth <= innerWidth")

            page.goto("/workbench#/workflows/greeting")
            side = page.locator(".wf-side")
            expect(side).to_be_visible()
            if width > 1000:  # beside the steps, the palette scrolls on its own, and its scrollbar is always shown
                assert side.evaluate("s => getComputedStyle(s).overflowY") == "scroll"
                assert side.evaluate("s => s.scrollHeight > s.clientHeight"), width  # more entries than fit: it scrolls
            assert page.js_errors == []
        finally:
            page.context.close()


def page_height(page) -> int:
    return page.evaluate("document.documentElement.scrollHeight")


def test_the_rules_page_is_the_window_at_1280x800_and_its_panels_scroll_inside(author_page, screenshots):
    page = author_page
    page.set_viewport_size({"width": 1280, "height": 800})
    open_ruleset(page, "reception")
    expect(page.get_by_test_id("rule-list").locator(".rule-item")).to_have_count(32)
    assert page_height(page) == 800  # the page does not scroll as a whole
    editor = page.locator(".editor-host:not([hidden])")
    for panel in (editor, page.get_by_test_id("rule-list"), page.locator(".card.try"), page.get_by_test_id("deploy"),
                  page.locator("header.top")):
        expect(panel).to_be_in_viewport()
    box = editor.bounding_box()
    assert box["height"] >= 200 and box["y"] + box["height"] <= 800, box  # a usable editor, inside the window
    # the editor scrolls its 400 lines itself; the window does not move
    scroller = editor.locator(".cm-scroller")
    assert scroller.evaluate("s => s.scrollHeight > s.clientHeight")
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.wheel(0, 2000)
    page.wait_for_function("document.querySelector('.editor-host:not([hidden]) .cm-scroller').scrollTop > 0")
    assert page.evaluate("window.scrollY") == 0

    # The tests' results open in the side column, which scrolls inside; the page still fits.
    page.get_by_test_id("run-tests").click()
    expect(page.get_by_test_id("tests-summary")).to_have_text("✓ All 24 scenarios pass")
    expect(page.get_by_test_id("tests-summary")).to_be_in_viewport()
    right = page.locator(".columns > .right")
    assert right.evaluate("r => r.scrollHeight > r.clientHeight")  # more than fits: it scrolls, not the page
    assert page_height(page) == 800
    expect(page.locator("header.top")).to_be_in_viewport()
    page.screenshot(path=str(screenshots / "workbench-rules-1280x800.png"))


def test_a_value_shows_its_unit_and_limits_and_a_negative_distance_is_refused(author_page, gateway, screenshots):
    page = author_page
    page.goto("/workbench#/knowledge/kinect1")
    value = page.get_by_test_id("value-kinect1.distanceToEntrance")
    expect(value).to_have_value("3.3")
    expect(page.get_by_test_id("unit-kinect1.distanceToEntrance")).to_have_text("metres")
    expect(page.get_by_test_id("kind-kinect1.distanceToEntrance")).to_have_text("number in metres, 0 to 20")
    error = page.locator("#err-kinect1-distanceToEntrance")

    value.fill("far away")
    expect(error).to_have_text("distanceToEntrance: 'far away' is not a number in metres from 0 to 20, e.g. 3.3")
    expect(page.get_by_test_id("save-kinect1.distanceToEntrance")).to_be_disabled()
    value.fill("-1")
    expect(error).to_have_text("distanceToEntrance: -1 metres is below the least allowed, 0 metres; "
                               "give a number in metres from 0 to 20, e.g. 3.3")
    expect(page.get_by_test_id("save-kinect1.distanceToEntrance")).to_be_disabled()
    page.screenshot(path=str(screenshots / "knowledge-value-limits.png"))
    value.fill("2.5")
    expect(error).to_have_text("")
    expect(page.get_by_test_id("save-kinect1.distanceToEntrance")).to_be_enabled()

    # The gateway refuses it too, with the same reason, and changes nothing.
    with gateway.rest() as client:
        before = client.get("/api/knowledge/ontology").json()
        r = client.put("/api/knowledge/individuals/kinect1/values/distanceToEntrance", json={"value": "-1"})
        assert r.status_code == 422
        assert r.json()["errors"][0]["message"].startswith("distanceToEntrance: -1 metres is below the least allowed, 0 metres")
        assert client.get("/api/knowledge/ontology").json() == before


def test_owner_pages_speak_plainly(author_page, gateway):
    page = author_page
    # Live: no developer words, and the missing robot connection is explained.
    page.goto("/workbench#/live")
    expect(page.get_by_test_id("live-status")).to_have_text("● Live")
    expect(page.get_by_test_id("robot-status")).to_contain_text("No robot is connected to this gateway")
    text = page.locator("main").inner_text()
    for developer_words in ("REST", "/api/", "post to", "process"):
        assert developer_words not in text, developer_words

    # Workflows: each palette entry once, with a plain name; a new step's problem names the field
    # as the form labels it.
    page.goto("/workbench#/workflows/greeting")
    palette = page.get_by_test_id("wf-palette")
    expect(palette.locator(".wf-entry", has_text="say")).to_have_count(1)
    expect(palette.locator(".wf-entry", has_text="say")).to_have_text("robot Pepper: say")
    expect(palette.locator(".wf-entry[data-module=fire_reception_rules]")).to_have_text("rules Fire the reception rules")
    expect(palette.locator(".wf-entry", has_text="Pepper: move to")).to_have_count(1)
    page.locator("[data-step=reception_rules]").first.click()
    page.get_by_role("button", name="Insert: Pepper: say").click()
    expect(page.get_by_test_id("wf-form").locator("[data-field='with.text']")).to_be_focused()
    problems = page.get_by_test_id("wf-problems")
    expect(problems).to_contain_text("field “text”: text is required")
    expect(problems).not_to_contain_text("with.text")
