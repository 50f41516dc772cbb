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
RDF_TYPE = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type"
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


SLOW_STREAM = "http://example.org/wb-live-slow"
SLOW_DRL = """package org.printeps.slowlive;

declare Thing
    id : String
end

rule "Hold until the test opens the gate"
when
    $t : Thing()
then
    // only the test's things (a deploy's warm-up fires made-up facts): mark started, wait for the gate
    if ($t.getId() != null && $t.getId().startsWith("PREFIX")) {
        try { new java.io.File("STARTED").createNewFile(); } catch (Exception e) { }
        long deadline = System.currentTimeMillis() + 120000;
        while (!new java.io.File("GATE").exists() && System.currentTimeMillis() < deadline) {
            try { Thread.sleep(5); } catch (InterruptedException e) { }
        }
    }
end
"""


def _slow_rule_set(gateway, tmp_path, name: str, prefix: str):
    """A rule set whose fires of the test's things hold until the gate file exists (a developer's
    rules: the file calls are not an author's, so it is deployed in-process, not over REST)."""
    started, gate = tmp_path / "started", tmp_path / "gate"
    drl = SLOW_DRL.replace("PREFIX", prefix).replace("STARTED", str(started)).replace("GATE", str(gate))
    gateway.engine.deploy(name, {"slow.drl": drl}, author="test", comment="a rule set the test holds")
    return started, gate


def test_skipped_windows_and_the_fire_queue_gauge_are_shown(author_page, gateway, tmp_path) -> None:
    """A query bound to a held rule set: the windows after the first coalesce, and each replaced one
    is listed as skipped; three REST fires of the held set fill its two threads and queue one, and
    the fire queues gauge shows it waiting, then drained once the gate opens."""
    import threading

    n = next(_parties)
    name, query, prefix = f"held{os.getpid()}x{n}", f"HeldQuery{os.getpid()}x{n}", f"held{os.getpid()}x{n}t"
    started, gate = _slow_rule_set(gateway, tmp_path, name, prefix)
    text = (f"REGISTER QUERY {query} AS\nPREFIX ex: <http://example.org/>\nSELECT ?s\n"
            f"FROM STREAM <{SLOW_STREAM}/{query}> [RANGE 1s STEP 1s]\nWHERE {{ ?s a ex:Thing . }}\n")
    fires: list[threading.Thread] = []
    answers: list[int] = []
    try:
        with gateway.rest() as client:
            r = client.post("/api/queries", json={"query": text, "comment": "held binding (test)", "rules": {
                "ruleset": name, "fact_type": "Thing", "fields": {"id": "s"}}})
            assert r.status_code == 201, r.text
        page = author_page
        open_live(page)
        with gateway.rest(CALLER_TOKEN) as client:
            for k in range(6):  # one new thing a second: the first window's fire holds, the rest coalesce
                r = client.post("/api/streams", json={"stream": f"{SLOW_STREAM}/{query}", "timestamp": 500 + 1000 * k,
                                                      "triples": [[f"http://example.org/{prefix}{k}", RDF_TYPE,
                                                                   "<http://example.org/Thing>"]]})
                assert r.status_code == 200, r.text
        assert started.exists()
        skipped = page.get_by_test_id("live-decisions").locator(f"li.skipped[data-query='{query}']")
        expect(skipped.first).to_contain_text(name)
        expect(skipped.first).to_contain_text("skipped")
        expect(skipped.first).to_contain_text(f"of {query} was not decided")
        expect(skipped.nth(1)).to_be_visible()  # each replaced window is said, not only the first

        def fire(k: int) -> None:
            with gateway.rest(CALLER_TOKEN) as http:
                answers.append(http.post(f"/api/rulesets/{name}/fire", timeout=120, json={
                    "facts": [{"type": "Thing", "id": f"{prefix}rest{k}"}]}).status_code)

        fires = [threading.Thread(target=fire, args=(k,), daemon=True) for k in range(3)]
        for thread in fires:
            thread.start()
        queue = page.get_by_test_id("fire-queues").locator(f"li[data-ruleset='{name}']")
        expect(queue).to_have_attribute("data-waiting", "1")  # two run on the set's two threads, one waits
        expect(queue).to_contain_text("1 waiting of 64, 2 running")
        expect(queue.locator("meter")).to_have_attribute("value", "1")
        gate.touch()
        for thread in fires:
            thread.join(60)
        # the two running fires answer; the queued one too, or 503 if it waited past api.max_wait_s
        # (the bulkhead's own rule) while the test read the gauge on a loaded machine
        assert len(answers) == 3 and answers.count(200) >= 2 and set(answers) <= {200, 503}, answers
        expect(queue).to_contain_text("0 waiting of 64, 0 running")
        assert page.js_errors == []
    finally:
        gate.touch()
        for thread in fires:
            thread.join(60)
        with gateway.rest() as client:
            client.delete(f"/api/queries/{query}")
