"""The knowledge editor in a real browser against the real gateway: Table 2 #12-#16 the way a teahouse
owner makes them (a number typed into a value cell, the SWRL rule text edited in the rule editor; no
Turtle), each followed by a check that the running gateway behaves differently (the workflows' robot
moves, the refill, the pour, Pellet's inference); a bad value and a bad rule change nothing live;
history, diff and rollback.

The session's gateway is shared with the other workbench tests: every test here puts the ontology
and the rules back as they were (a rollback to the versions it found).
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from playwright.sync_api import Page, expect

from wb_helpers import AUTHOR_TOKEN, CALLER_TOKEN, REFUSED_REQUEST, console_errors, new_page


@pytest.fixture()
def knowledge_restored(gateway) -> Iterator[None]:
    """The ontology and the SWRL rules as they were before the test, whatever it changed."""
    with gateway.rest() as client:
        before = {kind: client.get(f"/api/knowledge/{kind}").json() for kind in ("ontology", "swrl")}
    yield
    with gateway.rest() as client:
        for kind, was in before.items():
            if client.get(f"/api/knowledge/{kind}").json()["hash"] != was["hash"]:
                answer = client.post(f"/api/knowledge/{kind}/rollback", json={"version": was["version"]})
                assert answer.status_code == 200, answer.text


@pytest.fixture()
def page(browser, gateway, knowledge_restored) -> Iterator[Page]:
    page = new_page(browser, gateway, AUTHOR_TOKEN)
    yield page
    page.context.close()
    # refused requests (a 422 check) are the editor's to show, not script errors
    assert page.js_errors == [] and console_errors(page, REFUSED_REQUEST) == []


def _run(gateway, workflow: str, inputs: dict | None = None) -> list[dict]:
    with gateway.rest(CALLER_TOKEN) as client:
        run = client.post(f"/api/workflows/{workflow}/run", json={"inputs": inputs or {}}).json()
    assert run["status"] == "succeeded", run
    return [s for s in run["steps"] if s["type"] == "module" and s["status"] == "ok"]


def _moves(gateway) -> list[tuple[float, float]]:
    return [(round(float(s["params"]["x"]), 2), round(float(s["params"]["y"]), 2))
            for s in _run(gateway, "show_to_seat") if s["module"] == "move_to"]


def _refilled(gateway) -> bool:
    steps = _run(gateway, "serving", {"cups": [{"table": "table1", "empty_for_s": 20}]})
    return any("Refill the empty cups" in str(s["params"].get("prompt", "")) for s in steps)


def _poured(gateway) -> str:
    return next(s["params"]["name"] for s in _run(gateway, "prepare_drinks") if s["step_id"] == "pour")


def _child_seat(gateway, age: int) -> bool:
    with gateway.rest(CALLER_TOKEN) as client:
        body = {"individuals": [{"id": "kid", "types": ["Customer"], "properties": {"age": age}}]}
        inferred = client.post("/api/reason", json=body).json()["inferred"]
    return any(f["subject"].endswith("/kid") and f["predicate"].endswith("needsChildSeat") for f in inferred)


def _value(gateway, name: str):
    with gateway.rest(CALLER_TOKEN) as client:
        return client.get("/api/knowledge/values").json()["values"].get(name)


def _set_value(page: Page, name: str, value: str, comment: str) -> None:
    """Type a number into the value cell, say why, save; the view confirms it is live."""
    page.get_by_test_id(f"value-{name}").fill(value)
    page.get_by_label(f"Comment for {name}").fill(comment)
    page.get_by_test_id(f"save-{name}").click()
    expect(page.get_by_test_id("values-message")).to_contain_text(f"✓ {name} = {value} is live")


def _edit_rule(page: Page, number: int, old: str, new: str) -> None:
    page.get_by_test_id(f"edit-{number}").click()
    area = page.get_by_test_id(f"rule-text-{number}")
    area.fill(area.input_value().replace(old, new))


def test_table2_value_changes_in_the_browser_are_live_for_the_workflows(page: Page, gateway, screenshots):
    assert _moves(gateway) == [(2.0, 0.0), (3.5, 2.0)]
    assert _refilled(gateway) is False

    # #12 robot-to-human distance 1.0 -> 1.5, from the deep link of Pepper
    page.goto("/workbench/knowledge/pepper1")
    expect(page.get_by_role("heading", name="Knowledge · pepper1")).to_be_visible()
    expect(page.get_by_test_id("value-pepper1.robotToHumanDistance")).to_have_value("1.0")
    _set_value(page, "pepper1.robotToHumanDistance", "1.5", "Table 2 #12")
    assert _moves(gateway)[0] == (2.5, 0.0)

    # #13 robot-to-table distance 0.5 -> 0.8 (Enter saves too)
    cell = page.get_by_test_id("value-pepper1.robotToTableDistance")
    cell.fill("0.8")
    cell.press("Enter")
    expect(page.get_by_test_id("values-message")).to_contain_text("✓ pepper1.robotToTableDistance = 0.8 is live")
    assert _moves(gateway) == [(2.5, 0.0), (3.2, 2.0)]

    # #14 reaction time to empty cups 30 -> 15, found through the class tree (Service > Serving)
    page.locator("[data-class=Serving]").click()
    expect(page.get_by_role("heading", name="Knowledge · Serving")).to_be_visible()
    _set_value(page, "serving1.emptyCupReactionTime", "15", "Table 2 #14")
    assert _refilled(gateway) is True

    # a bad value: said as it is typed, not saved, nothing live changes
    page.goto("/workbench/knowledge/pepper1")
    cell = page.get_by_test_id("value-pepper1.robotToHumanDistance")
    cell.fill("abc")
    expect(page.locator("#err-pepper1-robotToHumanDistance")).to_have_text("robotToHumanDistance: 'abc' is not a number in metres from 0 to 5, e.g. 1.5")
    expect(cell).to_have_attribute("aria-invalid", "true")
    expect(page.get_by_test_id("save-pepper1.robotToHumanDistance")).to_be_disabled()
    cell.press("Enter")
    expect(page.get_by_test_id("values-message")).to_contain_text("Not saved: robotToHumanDistance: 'abc' is not a number in metres from 0 to 5, e.g. 1.5")
    expect(cell).to_have_value("abc")  # the owner's text is kept
    page.screenshot(path=str(screenshots / "knowledge-value-error.png"))
    assert _value(gateway, "pepper1.robotToHumanDistance") == 1.5
    assert _moves(gateway)[0] == (2.5, 0.0)


def test_table2_swrl_changes_in_the_browser_change_what_pellet_infers(page: Page, gateway, screenshots):
    assert _child_seat(gateway, 6) is True
    assert _poured(gateway) == "pour green tea x 2, 140 ml each"
    page.goto("/workbench/knowledge/rules")
    expect(page.get_by_test_id("readable-6")).to_have_text(
        "If ?c is a Customer and ?c's age is ?a and ?a < 7, then ?c needs child seat.")

    # #15 child-seat age threshold 7 -> 6: Check (Pellet), then Save
    _edit_rule(page, 6, "lessThan(?a, 7)", "lessThan(?a, 6)")
    page.get_by_test_id("check-6").click()
    expect(page.get_by_test_id("verdict-6")).to_contain_text("✓ Pellet: consistent")
    page.get_by_test_id("save-rule-6").click()
    expect(page.get_by_test_id("rules-message")).to_contain_text("✓ Rule 6 saved and live")
    expect(page.get_by_test_id("readable-6")).to_contain_text("?a < 6")
    assert _child_seat(gateway, 6) is False and _child_seat(gateway, 5) is True

    # #16 pour factor 0.8 -> 0.7: the drink-preparation workflow pours the inferred quantity
    _edit_rule(page, 7, "0.8)", "0.7)")
    page.get_by_test_id("check-7").click()
    expect(page.get_by_test_id("rule-changes")).to_have_text("cup1.pourQuantity: 140.0 → 122.5")
    page.get_by_test_id("save-rule-7").click()
    expect(page.get_by_test_id("rules-message")).to_contain_text("✓ Rule 7 saved and live")
    assert _poured(gateway) == "pour green tea x 2, 122.5 ml each"
    assert _value(gateway, "cup1.pourQuantity") == pytest.approx(122.5)

    # a bad rule: Pellet's verdict says where, Save refuses it, the text stays, nothing live changes
    with gateway.rest() as client:
        version = client.get("/api/knowledge/swrl").json()["version"]
    _edit_rule(page, 6, "age(?c, ?a)", "agee(?c, ?a)")
    page.get_by_test_id("check-6").click()
    verdict = page.get_by_test_id("verdict-6")
    expect(verdict).to_contain_text("Rule 6, line 17, column 15, at agee(?c, ?a): rule 6: 'agee' is not a class, property or built-in")
    page.get_by_test_id("save-rule-6").click()
    expect(verdict).to_contain_text("'agee' is not a class")
    page.get_by_test_id("rule-text-6").scroll_into_view_if_needed()
    page.screenshot(path=str(screenshots / "knowledge-rule-error.png"))
    expect(page.get_by_test_id("rule-text-6")).to_have_value(
        "Customer(?c), agee(?c, ?a), lessThan(?a, 6) -> needsChildSeat(?c, true)")
    with gateway.rest() as client:
        assert client.get("/api/knowledge/swrl").json()["version"] == version
    assert _child_seat(gateway, 5) is True


def test_what_pellet_infers_for_an_individual(page: Page, gateway):
    page.goto("/workbench/knowledge/cup1")
    result = page.get_by_test_id("infer-result")
    expect(result.locator("[data-inferred=pourQuantity]")).to_contain_text("pourQuantity = 140")
    expect(result.locator("[data-inferred=pourQuantity]")).to_contain_text("by rule 7")
    page.get_by_label("Individual", exact=True).select_option("pepper1")
    page.get_by_test_id("infer-button").click()
    expect(result.locator("[data-inferred='type Robot']")).to_contain_text("because Pepper is a kind of Robot")
    page.get_by_label("Class of the new individual").select_option("Customer")
    page.get_by_label("Property", exact=True).select_option("age")
    page.get_by_label("Value", exact=True).fill("4")
    page.get_by_test_id("try-button").click()
    expect(result.locator("[data-inferred=needsChildSeat]")).to_contain_text("needsChildSeat = true — by rule 6")


def test_history_diff_and_rollback(page: Page, gateway, screenshots):
    with gateway.rest() as client:
        first = client.get("/api/knowledge/ontology").json()["version"]
        answer = client.put("/api/knowledge/individuals/pepper1/values/robotToHumanDistance",
                            json={"value": "1.25", "comment": "a test change"})
        assert answer.status_code == 200, answer.text
    assert _moves(gateway)[0] == (2.25, 0.0)
    page.goto("/workbench/knowledge/history")
    versions = page.get_by_test_id("knowledge-versions")
    expect(versions.locator("tr.live-row")).to_contain_text("a test change")
    expect(page.get_by_test_id("diff")).to_contain_text('"1.25"^^xsd:decimal')
    page.screenshot(path=str(screenshots / "knowledge-history.png"), full_page=True)
    page.get_by_test_id(f"rollback-{first}").click()
    page.get_by_test_id(f"confirm-rollback-{first}").click()
    expect(page.locator(".flash")).to_contain_text(f"Rolled back: version {first} is live again")
    assert _value(gateway, "pepper1.robotToHumanDistance") == 1.0
    assert _moves(gateway)[0] == (2.0, 0.0)
    page.locator(".kind-tabs").get_by_role("link", name="SWRL rules").click()
    expect(page.locator(".kind-tabs").get_by_role("link", name="SWRL rules")).to_have_attribute("aria-current", "page")
    expect(page.get_by_test_id("knowledge-versions").locator("tr.live-row")).to_be_visible()


def test_a_caller_sees_the_knowledge_but_cannot_edit(browser, gateway):
    page = new_page(browser, gateway, CALLER_TOKEN)
    try:
        page.goto("/workbench/knowledge/pepper1")
        expect(page.get_by_test_id("value-pepper1.robotToHumanDistance")).to_be_visible()
        expect(page.get_by_text("authors can edit").first).to_be_visible()
        page.goto("/workbench/knowledge/rules")
        expect(page.get_by_test_id("readable-7")).to_be_visible()
        expect(page.get_by_test_id("edit-7")).to_have_count(0)
        assert page.js_errors == []
    finally:
        page.context.close()


@pytest.mark.parametrize("width", [1280, 768])
def test_the_knowledge_view_fits_laptop_and_tablet(browser, gateway, width, screenshots):
    page = new_page(browser, gateway, AUTHOR_TOKEN)
    try:
        page.set_viewport_size({"width": width, "height": 800})
        page.goto("/workbench/knowledge")
        expect(page.get_by_test_id("values")).to_be_visible()
        overflow = page.evaluate("document.documentElement.scrollWidth - document.documentElement.clientWidth")
        assert overflow <= 0
        page.screenshot(path=str(screenshots / f"knowledge-values-{width}.png"))
        page.goto("/workbench/knowledge/rules")
        expect(page.get_by_test_id("readable-6")).to_be_visible()
        page.screenshot(path=str(screenshots / f"knowledge-rules-{width}.png"))
        assert page.js_errors == []
    finally:
        page.context.close()


def test_keyboard_only_edits_a_value_and_a_rule(page: Page, gateway):
    page.goto("/workbench/knowledge/pepper1")
    cell = page.get_by_test_id("value-pepper1.robotToTableDistance")
    cell.focus()
    page.keyboard.press("Control+a")
    page.keyboard.type("9")
    page.keyboard.press("Escape")  # Escape puts the saved value back
    expect(cell).to_have_value("0.5")
    page.keyboard.press("Control+a")
    page.keyboard.type("0.6")
    page.keyboard.press("Tab")  # to the comment
    page.keyboard.type("keyboard only")
    page.keyboard.press("Tab")  # to Save
    page.keyboard.press("Enter")
    expect(page.get_by_test_id("values-message")).to_contain_text("✓ pepper1.robotToTableDistance = 0.6 is live")
    assert _value(gateway, "pepper1.robotToTableDistance") == 0.6

    page.goto("/workbench/knowledge/rules/7")
    page.get_by_test_id("edit-7").focus()
    page.keyboard.press("Enter")
    area = page.get_by_test_id("rule-text-7")
    expect(area).to_be_focused()
    page.keyboard.press("End")
    area.fill(area.input_value().replace("0.8)", "0.75)"))
    page.keyboard.press("Control+Enter")
    expect(page.get_by_test_id("rules-message")).to_contain_text("✓ Rule 7 saved and live")
    assert _value(gateway, "cup1.pourQuantity") == pytest.approx(131.25)


def test_a_rule_is_checked_as_it_is_typed_and_a_pellet_error_points_at_its_conclusion(page: Page, gateway):
    page.goto("/workbench/knowledge/rules/7")
    page.get_by_test_id("edit-7").click()
    area = page.get_by_test_id("rule-text-7")
    area.fill("Cup(?c) -> cupCapacity(?c, 300")  # no Check click: typing is enough
    expect(page.get_by_test_id("verdict-7")).to_contain_text("expected ',' or ')'")
    expect(area).to_be_focused()  # the cursor stays where the owner types
    area.fill('Cup(?c) -> cupCapacity(?c, "big")')
    verdict = page.get_by_test_id("verdict-7")
    expect(verdict).to_contain_text('column 12, at cupCapacity(?c, "big"): rule 7: Pellet finds the ontology and the rules inconsistent')
    area.fill("Cup(?c) -> cupCapacity(?c, 300)")
    expect(verdict).to_contain_text("✓ Pellet: consistent")
    with gateway.rest() as client:
        assert "cupCapacity(?c, 300)" not in client.get("/api/knowledge/swrl").json()["text"]  # checked, not saved


def test_a_value_the_individual_lacks_is_added(page: Page, gateway):
    page.goto("/workbench/knowledge/hsr1")
    page.get_by_test_id("add-property").select_option("robotToHumanDistance")
    page.get_by_test_id("add-value").fill("x")
    expect(page.locator("#add-value-error")).to_have_text("robotToHumanDistance: 'x' is not a number in metres from 0 to 5, e.g. 1.2")
    page.get_by_test_id("add-value").fill("1.2")
    page.get_by_test_id("add-value-button").click()
    expect(page.locator(".flash")).to_contain_text("✓ hsr1.robotToHumanDistance = 1.2 is live")
    expect(page.get_by_test_id("value-hsr1.robotToHumanDistance")).to_have_value("1.2")
    assert _value(gateway, "hsr1.robotToHumanDistance") == 1.2
