"""The Live view in a real Chromium against the real gateway: entrance readings posted to the
stream draw each person's distance, the detection and the rules that fired appear as they happen,
a fired rule's link opens its decision (also by deep link), pause holds new events until resume."""

from __future__ import annotations

import itertools
import os
import time

from playwright.sync_api import expect

from wb_helpers import AUTHOR_TOKEN, CALLER_TOKEN, new_page

ENTRANCE = "http://printeps.org/cafe/entrance"
_parties = itertools.count(1)


def party(prefix: str) -> tuple[str, str]:
    n = next(_parties)
    return f"{prefix}{os.getpid()}x{n}a", f"{prefix}{os.getpid()}x{n}b"


def post_party(gateway, people: tuple[str, str]) -> None:
    """Two people walking up to the entrance, one reading a second, stamped after anything posted
    before (the stream's clock only moves forward)."""
    t0 = int(time.time() * 1000)
    with gateway.rest(CALLER_TOKEN) as http:
        for i, d in enumerate([5.0, 4.0, 3.0, 2.0, 1.8, 1.8]):
            response = http.post("/api/streams", json={"stream": ENTRANCE, "timestamp": t0 + 1000 * i, "message": {
                "id": f"e{t0}-{i}", "number_of_customers": 2, "customers": [
                    {"id": people[0], "distance": d, "age": 34, "gender": "female"},
                    {"id": people[1], "distance": d + 0.05, "age": 36, "gender": "female"}]}})
            assert response.status_code == 200, response.text


def open_live(page) -> None:
    page.goto("/workbench#/live")
    expect(page.get_by_test_id("live-status")).to_have_text("● Live")
    expect(page.locator(".layout")).to_have_class("layout no-sidebar")


def test_readings_fill_the_plot_and_a_decision_link_opens_the_decision(author_page, gateway) -> None:
    page = author_page
    open_live(page)
    people = party("w")
    post_party(gateway, people)

    legend = page.get_by_test_id("live-legend")
    for person in people:
        expect(legend.locator(f"li[data-person='{person}']")).to_contain_text("m")
        expect(page.locator(f"[data-testid=plot-svg] g.person[data-person='{person}'] polyline")).to_have_count(1)
    expect(legend.locator(f"li[data-person='{people[0]}']")).to_contain_text("1.80 m")
    expect(page.locator("[data-testid=plot-svg] desc")).to_contain_text(people[0])
    expect(page.get_by_test_id("latest-reading")).to_contain_text("Latest entrance reading received at")
    expect(page.get_by_test_id("threshold")).to_contain_text("entrance: 3.3 m")  # the ontology's value
    detection = page.get_by_test_id("live-detections").locator("li.detection", has_text=people[0])
    expect(detection).to_have_count(1)  # one detection going on, however many windows saw it
    expect(detection).to_contain_text("CustomerDetectionQuery")
    decision = page.get_by_test_id("live-decisions").locator("li.decision").first
    expect(decision).to_contain_text("reception")
    expect(decision).to_contain_text("Fired:")
    expect(page.get_by_test_id("live-actions").locator("li.action-item").first).to_be_visible()

    decision_id = decision.get_attribute("data-decision")
    assert decision_id
    decision.get_by_role("link", name="Open the decision").click()
    expect(page).to_have_url(f"{gateway.base_url}/workbench#/decisions/{decision_id}")
    card = page.get_by_test_id("decision")
    expect(card.get_by_role("heading", level=1)).to_contain_text(decision_id)
    expect(card.get_by_test_id("fired")).to_be_visible()
    expect(card.get_by_test_id("facts")).to_contain_text(people[0])
    expect(page.locator("tr.current-decision")).to_have_count(1)

    # the same decision by its deep link; the Live view comes back with what it had seen (replay)
    page.goto(f"/workbench/decisions/{decision_id}")
    expect(page.get_by_test_id("decision").get_by_role("heading", level=1)).to_contain_text(decision_id)
    page.get_by_role("link", name="Back to Live").click()
    expect(page.get_by_test_id("live-legend").locator(f"li[data-person='{people[0]}']")).to_be_visible()


def test_an_unknown_decision_says_so(author_page) -> None:
    author_page.goto("/workbench#/decisions/000000000000000000000000")
    expect(author_page.get_by_test_id("decision").get_by_role("alert")).to_contain_text("There is no decision")


def test_pause_holds_new_events_until_resume(author_page, gateway) -> None:
    page = author_page
    open_live(page)
    pause = page.get_by_test_id("pause")
    pause.press("Enter")  # keyboard: the button is reachable and labelled
    expect(pause).to_have_attribute("aria-pressed", "true")
    people = party("z")
    post_party(gateway, people)
    expect(page.get_by_test_id("paused-note")).to_contain_text("new event(s) held")
    expect(page.get_by_test_id("live-legend").locator(f"li[data-person='{people[0]}']")).to_have_count(0)
    pause.click()
    expect(pause).to_have_attribute("aria-pressed", "false")
    expect(page.get_by_test_id("live-legend").locator(f"li[data-person='{people[0]}']")).to_be_visible()
    expect(page.get_by_test_id("paused-note")).to_have_text("")


def test_a_page_without_an_accepted_token_is_not_connected(browser, gateway) -> None:
    page = new_page(browser, gateway, AUTHOR_TOKEN)
    try:
        open_live(page)
        assert page.js_errors == []
        # the token goes away (signed out elsewhere): the feed refuses the next connection
        page.evaluate("localStorage.setItem('printeps.workbench.token', 'not-a-token')")
        page.evaluate("location.hash = '#/decisions'")
        expect(page.get_by_test_id("decisions")).to_be_visible()
        page.evaluate("location.hash = '#/live'")
        expect(page.get_by_test_id("live-status")).to_contain_text("Not connected")
        expect(page.get_by_role("button", name="Reconnect")).to_be_visible()
    finally:
        page.context.close()
