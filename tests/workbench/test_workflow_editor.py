"""The visual workflow editor (Workflows section of the workbench) in a real Chromium against the
real gateway: Table-2 change requests made the owner's way (palette, forms, clicks and keys; no
YAML typed), keyboard and drag-and-drop editing, checks as you type, live save with conflicts,
versions and rollback, runs on the simulated robots; and the palette API it is built from.

Every test works on its own copy of a teahouse workflow (saved under a new name through REST),
so the tests do not depend on each other or on their order.
"""

from __future__ import annotations

import itertools
import json
import os
import time

import pytest
from playwright.sync_api import Page, expect

from gateway.config import PROJECT_ROOT
from wb_helpers import AUTHOR_TOKEN, CALLER_TOKEN, OTHER_AUTHOR_TOKEN, REFUSED_REQUEST, console_errors

pytestmark = pytest.mark.browser

WORKFLOWS = PROJECT_ROOT / "workflows"
_copies = itertools.count(1)


def copy_workflow(gateway, file_name: str) -> tuple[str, str]:
    """Save the teahouse workflow ``file_name`` under a fresh name; returns (name, its text)."""
    text = (WORKFLOWS / file_name).read_text(encoding="utf-8")
    original = next(line.split(":", 1)[1].strip() for line in text.splitlines() if line.startswith("workflow:"))
    name = f"{original}_{os.getpid()}_{next(_copies)}"
    text = text.replace(f"workflow: {original}\n", f"workflow: {name}\n", 1)
    with gateway.rest() as client:
        response = client.put(f"/api/workflows/{name}", json={"text": text, "comment": "copy for a test"})
        assert response.status_code == 201, response.text
    return name, text


def current(gateway, name: str) -> dict:
    with gateway.rest(CALLER_TOKEN) as client:
        response = client.get(f"/api/workflows/{name}")
        response.raise_for_status()
        return response.json()


def run(gateway, name: str, inputs: dict | None = None) -> dict:
    with gateway.rest(CALLER_TOKEN) as client:
        response = client.post(f"/api/workflows/{name}/run", json={"inputs": inputs or {}})
        response.raise_for_status()
        return response.json()


def step_ids(result: dict) -> list[str]:
    return [s["step_id"] for s in result["steps"]]


@pytest.fixture()
def author_page(author_page: Page) -> Page:
    """The signed-in author's page, also failing on console errors (HTTP answers the editor
    handles itself, such as a 409 conflict or a 422 check, are not errors of the page)."""
    yield author_page
    assert console_errors(author_page, f"{REFUSED_REQUEST}: the server responded with a status of 4") == []


def open_workflow(page: Page, name: str) -> None:
    """Open by the deep link a shared address would be."""
    page.goto(f"/workbench/workflows/{name}")
    expect(page.get_by_test_id("wf-status")).to_have_text("✓ No problems")


def step_button(page: Page, step_id: str):
    return page.locator(f"button.wf-step-main[data-step='{step_id}']")


def steps_of(page: Page, process: str) -> list[str]:
    return page.locator(f".wf-process[data-process='{process}'] > .wf-list > ol > li.wf-step").evaluate_all(
        "items => items.map(li => li.dataset.step)")


def save(page: Page, comment: str, version: int) -> None:
    expect(page.get_by_test_id("wf-status")).to_have_text("✓ No problems")
    page.get_by_label("What did you change? (comment for the version)").fill(comment)
    page.get_by_test_id("wf-save").click()
    expect(page.get_by_test_id("wf-save-message")).to_contain_text(f"Saved: version {version} is live")


def run_in_editor(page: Page, inputs: str = "") -> list[str]:
    """Run from the editor and wait until the trace is complete; returns the traced step ids."""
    if inputs:
        page.locator(".wf-run summary").click()
        page.get_by_label("Run inputs (JSON; empty: the workflow's defaults)").fill(inputs)
    page.get_by_test_id("wf-run").click()
    expect(page.get_by_test_id("wf-run-status")).to_contain_text("succeeded")
    return page.locator("[data-testid=wf-trace] li").evaluate_all("items => items.map(li => li.dataset.step)")


# ---------------------------------------------------------------- Table 2, the owner's way


def test_table2_1_say_before_going_to_the_table(author_page: Page, gateway, screenshots):
    name, _ = copy_workflow(gateway, "2_show_to_seat.yaml")
    page = author_page
    open_workflow(page, name)
    expect(page).to_have_url(f"{gateway.base_url}/workbench#/workflows/{name}")  # the deep link opened it
    step_button(page, "go_to_table").click()
    page.get_by_label("Where new steps go").select_option("before")
    expect(page.get_by_test_id("wf-insertion")).to_have_text("Inserting before step “go_to_table”.")
    page.get_by_role("button", name="Insert: Pepper: say").click()  # the palette: robot service x interface
    form = page.get_by_test_id("wf-form")
    text = form.locator("[data-field='with.text']")
    expect(text).to_be_focused()
    expect(form.locator("[data-field-box='with.text'] .wf-field-error")).to_have_text("text is required")
    text.fill("I will show you to your table. Please follow me.")
    form.locator("[data-field=id]").fill("announce_move")
    expect(form.locator("[data-field=robot] option")).to_have_text(["pepper"])  # only Pepper can speak
    assert steps_of(page, "lead_to_table") == ["table_distance", "announce_move", "go_to_table"]
    save(page, "Table 2 #1: speak before moving", 2)

    stored = current(gateway, name)
    assert stored["version"] == 2
    assert stored["text"].index("announce_move") < stored["text"].index("id: go_to_table")
    traced = run_in_editor(page)
    assert traced.index("announce_move") < traced.index("go_to_table")
    expect(page.locator("[data-testid=wf-trace] li[data-step=announce_move]")).to_contain_text("Please follow me.")
    expect(page.locator("li.wf-step.ran[data-step=announce_move]")).to_have_count(1)  # highlighted in the view
    page.screenshot(path=str(screenshots / "workflow-editor-run.png"), full_page=True)
    result = run(gateway, name)
    said_at = step_ids(result).index("announce_move")
    assert result["steps"][said_at]["module"] == "say" and said_at < step_ids(result).index("go_to_table")


def test_table2_5_a_new_wait_module_and_its_step(author_page: Page, gateway):
    name, _ = copy_workflow(gateway, "3_take_order.yaml")
    page = author_page
    open_workflow(page, name)
    step_button(page, "confirm_order").click()
    page.get_by_label("Where new steps go").select_option("before")
    page.get_by_role("button", name="Insert: Wait").click()  # no wait module yet: the palette adds one
    # the new module and its palette entry are one row now, named plainly
    expect(page.locator(".wf-entry[data-module=pause]")).to_have_accessible_name("Insert: Wait")
    expect(page.locator(".wf-entry[data-entry=wait]")).to_have_count(0)
    page.get_by_test_id("wf-form").locator("[data-field=id]").fill("let_them_finish")
    page.get_by_role("button", name="Edit module pause").click()
    seconds = page.get_by_test_id("wf-form").locator("[data-field='params.seconds']")
    seconds.fill("0.2")
    save(page, "Table 2 #5: let them finish", 2)

    assert "pause:" in current(gateway, name)["text"]
    traced = run_in_editor(page)
    assert traced.index("ask_order") < traced.index("let_them_finish") < traced.index("confirm_order")
    expect(page.locator("[data-testid=wf-trace] li[data-step=let_them_finish]")).to_contain_text("0.2 s")
    result = run(gateway, name)
    waited = next(s for s in result["steps"] if s["step_id"] == "let_them_finish")
    assert waited["kind"] == "wait" and waited["output"] == {"waited": 0.2}


def test_table2_3_an_else_arm_with_a_performance(author_page: Page, gateway):
    name, _ = copy_workflow(gateway, "4_prepare_drinks.yaml")
    page = author_page
    open_workflow(page, name)
    page.get_by_role("button", name="Add new steps at the end of the else arm of any_order").click()
    expect(page.get_by_test_id("wf-insertion")).to_have_text("Inserting at the end of the else arm of any_order.")
    page.get_by_role("button", name="Insert: Jaco2: gesture / motion").click()  # the workflow's jaco2_motion module
    form = page.get_by_test_id("wf-form")
    form.locator("[data-field='with.name']").fill("tea ceremony performance")
    form.locator("[data-field=id]").fill("idle_performance")
    save(page, "Table 2 #3: perform while idle", 2)

    traced = run_in_editor(page, '{"orders": []}')
    assert "idle_performance" in traced and "pour" not in traced
    result = run(gateway, name, {"orders": []})
    performed = next(s for s in result["steps"] if s["step_id"] == "idle_performance")
    assert performed["params"]["name"] == "tea ceremony performance" and performed["actor"] == "jaco2"
    assert "pour" in step_ids(run(gateway, name))  # with an order, the then-arm as before


def test_table2_7_visit_and_speak_before_the_bill(author_page: Page, gateway):
    name, _ = copy_workflow(gateway, "6_settle_bill.yaml")
    page = author_page
    open_workflow(page, name)
    step_button(page, "settle_bill").click()
    page.get_by_label("Where new steps go").select_option("before")
    page.get_by_role("button", name="Insert: Pepper: move to").click()
    form = page.get_by_test_id("wf-form")
    form.locator("[data-field='with.x']").fill("${input.table.x - 0.5}")
    form.locator("[data-field='with.y']").fill("${input.table.y}")
    form.locator("[data-field=id]").fill("go_to_table")
    page.get_by_label("Where new steps go").select_option("after")  # after the new go_to_table
    page.get_by_role("button", name="Insert: Pepper: say").click()
    form.locator("[data-field='with.text']").fill("Thank you. Our staff will bring your bill now.")
    form.locator("[data-field=id]").fill("announce_bill")
    assert steps_of(page, "settle") == ["go_to_table", "announce_bill", "settle_bill"]
    save(page, "Table 2 #7: visit and speak before the bill", 2)
    assert run_in_editor(page) == ["go_to_table", "announce_bill", "settle_bill"]
    expect(page.locator("[data-testid=wf-trace] li[data-step=go_to_table]")).to_contain_text("(3.5, 2)")


def test_a_place_is_picked_from_what_the_run_is_given_and_told_in_words(author_page: Page, gateway):
    """#7 without typing an expression: "+ add at the start", then the place picked in words."""
    name, _ = copy_workflow(gateway, "6_settle_bill.yaml")
    page = author_page
    open_workflow(page, name)
    form = page.get_by_test_id("wf-form")
    # the canvas tells the prompt's reference in words, not as ${input.table.id}
    expect(step_button(page, "settle_bill").locator(".wf-summary")).to_have_text("staff_task: Settle the bill of [the table]")
    step_button(page, "settle_bill").click()  # a staff task whose prompt already names the table
    expect(form.get_by_text("Uses the table (table1).")).to_be_visible()

    page.get_by_role("button", name="Add new steps at the start of the process settle").click()
    expect(page.get_by_test_id("wf-insertion")).to_have_text("Inserting at the start of the process settle.")
    page.get_by_role("button", name="Insert: Pepper: move to").click()
    picker = form.get_by_label("Pick a value for location")
    assert picker.locator("option").all_inner_texts() == [
        "Pick a value…", "the table (table1)", "the table's x (4)", "the table's y (2)"]
    picker.select_option(label="the table (table1)")
    location = form.locator("[data-field='with.location']")
    expect(location).to_have_value("${input.table.id}")
    expect(form.get_by_text("Uses the table (table1).")).to_be_visible()

    # A name the run is not given is named, in words, with what it is given (a note: nothing is refused).
    location.fill("${input.tabel.id}")
    expect(form).to_contain_text("“tabel” is not among what the run is given (table) or what earlier steps found")
    location.fill("")
    picker.select_option(label="the table (table1)")
    page.get_by_role("button", name="Insert: Pepper: say").click()  # after the move (new steps go after it)
    text = form.locator("[data-field='with.text']")
    text.fill("Thank you. Your bill for ")
    form.get_by_label("Pick a value for text").select_option(label="the table (table1)")
    expect(text).to_have_value("Thank you. Your bill for ${input.table.id}")
    assert steps_of(page, "settle") == ["move_to", "say", "settle_bill"]
    save(page, "visit the table first", 2)
    assert run_in_editor(page) == ["move_to", "say", "settle_bill"]
    expect(page.locator("[data-testid=wf-trace] li[data-step=move_to]")).to_contain_text("table1")
    expect(page.locator("[data-testid=wf-trace] li[data-step=say]")).to_contain_text("Your bill for table1")


def test_unsaved_edits_can_be_tried_without_going_live(author_page: Page, gateway):
    name, _ = copy_workflow(gateway, "7_thanking.yaml")
    page = author_page
    open_workflow(page, name)
    step_button(page, "thank").click()
    page.get_by_test_id("wf-form").locator("[data-field='with.text']").fill("Thanks, see you!")
    page.get_by_test_id("wf-try").click()
    expect(page.get_by_test_id("wf-run-status")).to_contain_text("Run try-")
    expect(page.get_by_test_id("wf-run-status")).to_contain_text("of your unsaved edits succeeded")
    expect(page.locator("[data-testid=wf-trace] li[data-step=thank]")).to_contain_text("Thanks, see you!")
    assert current(gateway, name)["version"] == 1
    live = next(s for s in run(gateway, name)["steps"] if s["step_id"] == "thank")
    assert live["params"]["text"] == "Thank you very much. Please come again."
    with gateway.rest(CALLER_TOKEN) as client:  # trying is an author's action
        assert client.post("/api/workflows/try", json={"text": "workflow: x"}).status_code == 403
    with gateway.rest() as client:
        bad = client.post("/api/workflows/try", json={"text": "workflow: x"})
        assert bad.status_code == 422 and bad.json()["problems"]


def test_a_new_process_in_a_service(author_page: Page, gateway):
    name, _ = copy_workflow(gateway, "7_thanking.yaml")
    page = author_page
    open_workflow(page, name)
    new_process = page.get_by_label("Name of a new process of service farewell")
    new_process.fill("see_off")
    new_process.press("Enter")
    expect(page.locator(".wf-new-process .wf-field-error")).to_have_text("There is already a process “see_off”.")
    new_process.fill("wave_goodbye")
    new_process.press("Enter")
    expect(page.get_by_test_id("wf-problems")).to_contain_text("processes.wave_goodbye.steps")  # empty until a step
    expect(page.get_by_test_id("wf-insertion")).to_have_text("Inserting at the end of the process wave_goodbye.")
    page.get_by_role("button", name="Insert: Pepper: gesture / motion").click()  # the workflow's gesture module
    page.get_by_test_id("wf-form").locator("[data-field='with.name']").fill("wave")
    save(page, "wave goodbye after seeing them off", 2)
    assert step_ids(run(gateway, name))[-1] == "gesture"


def test_a_process_is_renamed_and_removed_in_the_process_view(author_page: Page, gateway, screenshots):
    """Rename keeps the process's place and its service's list; Remove takes its steps too, and
    Undo brings it back."""
    name, _ = copy_workflow(gateway, "7_thanking.yaml")
    page = author_page
    open_workflow(page, name)
    page.get_by_role("button", name="Rename process see_off").click()
    field = page.get_by_label("New name of process see_off")
    field.fill("2bad")
    field.press("Enter")
    expect(page.locator(".wf-rename .wf-field-error")).to_contain_text("letters, digits and _")
    field.press("Escape")
    expect(page.get_by_role("button", name="Rename process see_off")).to_be_focused()
    page.get_by_role("button", name="Rename process see_off").click()
    page.get_by_label("New name of process see_off").fill("bid_farewell")
    page.get_by_label("New name of process see_off").press("Enter")
    expect(page.get_by_role("button", name="Rename process bid_farewell")).to_be_focused()
    page.screenshot(path=str(screenshots / "workflow-editor-rename.png"))
    assert steps_of(page, "bid_farewell") == ["go_to_door", "thank", "bow", "back_to_counter"]
    page.get_by_role("button", name="Remove process bid_farewell").click()
    expect(page.locator(".wf-process[data-process='bid_farewell']")).to_have_count(0)
    expect(page.get_by_test_id("wf-problems")).to_contain_text("services.farewell.processes")  # now empty
    page.get_by_role("button", name="Undo the last change").click()
    assert steps_of(page, "bid_farewell") == ["go_to_door", "thank", "bow", "back_to_counter"]
    save(page, "the process says what it does", 2)
    text = current(gateway, name)["text"]
    assert "  bid_farewell:\n" in text and "processes: [bid_farewell]" in text and "see_off" not in text
    assert step_ids(run(gateway, name)) == ["go_to_door", "thank", "bow", "back_to_counter"]


def test_the_variables_of_a_set_step_are_edited_in_its_form(author_page: Page, gateway, screenshots):
    name, text = copy_workflow(gateway, "7_thanking.yaml")
    text = text.replace("      - id: thank\n",
                        "      # the words they hear\n      - id: words\n        set: {greeting: Thank you}\n      - id: thank\n", 1)
    text = text.replace('"Thank you very much. Please come again."', '"${greeting} very much."', 1)
    with gateway.rest() as client:
        assert client.put(f"/api/workflows/{name}", json={"text": text, "comment": "a set step"}).status_code == 201
    page = author_page
    open_workflow(page, name)
    step_button(page, "words").click()
    expect(page.get_by_label("Value of variable greeting")).to_have_value("Thank you")
    page.get_by_label("Value of variable greeting").fill("Many thanks")
    page.get_by_role("button", name="+ Add a variable").click()
    expect(page.get_by_label("Name of variable value")).to_be_focused()
    page.get_by_label("Name of variable value").fill("greeting")
    page.get_by_label("Name of variable value").press("Tab")
    expect(page.locator(".wf-variable .wf-field-error").nth(1)).to_have_text("The step already sets “greeting”.")
    page.get_by_label("Name of variable value").fill("times")
    page.get_by_label("Name of variable value").press("Tab")
    expect(page.get_by_label("Value of variable times")).to_be_focused()
    page.get_by_label("Value of variable times").fill("2")
    page.screenshot(path=str(screenshots / "workflow-editor-set-step.png"))
    save(page, "warmer thanks", 3)
    saved = current(gateway, name)["text"]
    assert "set: {greeting: Many thanks, times: 2}" in saved
    assert "      # the words they hear\n      - id: words\n" in saved  # a visual save keeps the comments
    steps = run(gateway, name)["steps"]
    assert next(s for s in steps if s["step_id"] == "words")["output"] == {"greeting": "Many thanks", "times": 2}
    page.get_by_role("button", name="Remove variable times").click()
    expect(page.get_by_label("Value of variable times")).to_have_count(0)
    step_button(page, "bow").click()
    page.get_by_role("button", name="Insert: Set variables").click()  # a new set step from the palette
    expect(page.get_by_label("Name of variable value")).to_be_focused()
    assert steps_of(page, "see_off") == ["go_to_door", "words", "thank", "bow", "set", "back_to_counter"]


def test_the_robot_of_a_step_is_chosen_from_the_robots(author_page: Page, gateway):
    name, _ = copy_workflow(gateway, "7_thanking.yaml")
    page = author_page
    open_workflow(page, name)
    step_button(page, "bow").click()
    robot = page.get_by_test_id("wf-form").locator("[data-field=robot]")
    expect(robot.locator("option")).to_have_text(["hsr", "jaco2", "pepper"])  # every robot that can gesture
    expect(robot).to_have_value("pepper")
    robot.select_option("jaco2")
    expect(page.get_by_test_id("wf-form").locator("[data-field=module]")).to_have_value("jaco2_gesture")
    save(page, "the arm bows", 2)
    bow = next(s for s in run(gateway, name)["steps"] if s["step_id"] == "bow")
    assert bow["actor"] == "jaco2" and bow["params"]["robot"] == "jaco2"


def test_a_robot_new_to_the_workflow_comes_with_its_actor(author_page: Page, gateway):
    name, _ = copy_workflow(gateway, "4_prepare_drinks.yaml")
    page = author_page
    open_workflow(page, name)
    page.get_by_role("button", name="Add new steps at the end of the process prepare").click()
    page.get_by_role("button", name="Insert: Pepper: say").click()
    page.get_by_test_id("wf-form").locator("[data-field='with.text']").fill("Your drinks are coming.")
    save(page, "Pepper tells the drinks are coming", 2)
    text = current(gateway, name)["text"]
    assert "pepper: {kind: robot, label: Pepper}" in text and "service: /pepper/speak" in text
    said = next(s for s in run(gateway, name)["steps"] if s["module"] == "say")
    assert said["actor"] == "pepper" and said["params"] == {"robot": "pepper", "text": "Your drinks are coming."}


def test_table2_8_fire_the_seat_info_rules_after_the_welcome(author_page: Page, gateway):
    from agile_harness import SEAT_INFO_DRL, TABLES

    ruleset = f"seat_info_wf{os.getpid()}"  # not the Table 2 browser test's name: both may share a worker's gateway
    response = gateway.deploy(ruleset, {"seat_info.drl": SEAT_INFO_DRL}, "Table 2 #8: seat information")
    assert response.status_code == 201, response.text
    name, _ = copy_workflow(gateway, "1_greeting.yaml")
    page = author_page
    open_workflow(page, name)
    step_button(page, "reception_rules").click()
    page.get_by_role("button", name="Insert: Fire business rules").click()
    form = page.get_by_test_id("wf-form")
    form.locator("[data-field='with.facts']").fill("${input.tables}")
    form.locator("[data-field=id]").fill("seat_info_rules")
    page.get_by_role("button", name="Edit module fire_rules").click()
    form.locator("[data-field=name]").fill("fire_seat_info_rules")
    form.locator("[data-field=name]").press("Enter")  # renamed, with the step that uses it
    expect(page.get_by_role("button", name="Insert a fire_seat_info_rules step (rules)")).to_be_visible()
    form.locator("[data-field=ruleset]").select_option(ruleset)  # only deployed rule sets are offered
    form.get_by_label("Rule action (e.g. say)").fill("say")
    form.get_by_label("Module that performs it").select_option("say")
    form.get_by_role("button", name="Add action").click()
    expect(form).to_contain_text("say → say")
    save(page, "Table 2 #8: tell the free tables", 2)

    traced = run_in_editor(page, json.dumps({"tables": TABLES}))
    assert traced.index("reception_rules") < traced.index("seat_info_rules")
    expect(page.locator("[data-testid=wf-trace]")).to_contain_text("2 free tables for you today")
    result = run(gateway, name, {"tables": TABLES})
    said = [s["params"].get("text", "") for s in result["steps"] if s["module"] == "say"]
    assert "fire_seat_info_rules:" in current(gateway, name)["text"]
    welcome = next(i for i, text in enumerate(said) if "Welcome" in text)
    assert welcome < next(i for i, text in enumerate(said) if "2 free tables for you today" in text)


# ---------------------------------------------------------------- editing by keyboard and mouse


def test_keyboard_reorders_and_removes_steps_with_focus_kept(author_page: Page, gateway):
    name, _ = copy_workflow(gateway, "3_take_order.yaml")
    page = author_page
    open_workflow(page, name)
    assert steps_of(page, "take_order") == ["ask_order", "confirm_order", "send_order"]
    step_button(page, "send_order").focus()
    page.keyboard.press("Alt+ArrowUp")
    assert steps_of(page, "take_order") == ["ask_order", "send_order", "confirm_order"]
    expect(step_button(page, "send_order")).to_be_focused()
    page.keyboard.press("Alt+ArrowDown")
    assert steps_of(page, "take_order") == ["ask_order", "confirm_order", "send_order"]
    expect(step_button(page, "send_order")).to_be_focused()
    page.get_by_role("button", name="Move step ask_order down").click()
    assert steps_of(page, "take_order") == ["confirm_order", "ask_order", "send_order"]
    step_button(page, "ask_order").focus()
    page.keyboard.press("Delete")
    assert steps_of(page, "take_order") == ["confirm_order", "send_order"]
    expect(step_button(page, "send_order")).to_be_focused()  # the step that took its place
    page.keyboard.press("Control+z")
    assert steps_of(page, "take_order") == ["confirm_order", "ask_order", "send_order"]
    expect(step_button(page, "ask_order")).to_be_focused()  # the step that came back
    page.get_by_role("button", name="Redo").click()
    assert steps_of(page, "take_order") == ["confirm_order", "send_order"]
    expect(page.get_by_test_id("wf-status")).to_have_text("✓ No problems")
    page.reload()  # unsaved edits survive a reload
    expect(page.get_by_test_id("wf-save-message")).to_contain_text(
        "Your unsaved edits (started from version 1) are back")
    expect(page.get_by_test_id("wf-status")).to_have_text("✓ No problems")
    assert steps_of(page, "take_order") == ["confirm_order", "send_order"]
    save(page, "reordered by keyboard", 2)
    text = current(gateway, name)["text"]
    assert "ask_order" not in text and text.index("id: confirm_order") < text.index("id: send_order")


def test_drag_and_drop_moves_a_step_and_inserts_from_the_palette(author_page: Page, gateway):
    name, _ = copy_workflow(gateway, "7_thanking.yaml")
    page = author_page
    open_workflow(page, name)
    page.locator("li.wf-step[data-step=bow]").drag_to(page.locator("li.wf-step[data-step=thank]"))
    assert steps_of(page, "see_off") == ["go_to_door", "bow", "thank", "back_to_counter"]
    page.get_by_role("button", name="Insert: Pepper: gesture").drag_to(
        page.locator("li.wf-step[data-step=back_to_counter]"))
    assert steps_of(page, "see_off") == ["go_to_door", "bow", "thank", "gesture", "back_to_counter"]
    page.get_by_test_id("wf-form").locator("[data-field='with.name']").fill("wave")
    save(page, "bow first, wave before leaving", 2)
    assert step_ids(run(gateway, name)) == ["go_to_door", "bow", "thank", "gesture", "back_to_counter"]


def test_a_bad_field_is_named_and_changes_nothing_live(author_page: Page, gateway):
    name, text = copy_workflow(gateway, "3_take_order.yaml")
    page = author_page
    open_workflow(page, name)
    step_button(page, "ask_order").click()
    form = page.get_by_test_id("wf-form")
    form.locator("[data-field=id]").fill("ask order")
    expect(page.get_by_test_id("wf-status")).to_have_text("✗ 1 problem")
    expect(page.get_by_test_id("wf-problems")).to_contain_text("Step “ask order”, field “id”")
    expect(form.locator("[data-field=id]")).to_have_attribute("aria-invalid", "true")
    expect(form.locator("[data-field-box=id] .wf-field-error")).to_contain_text("is not a valid name")
    page.get_by_test_id("wf-save").click()
    expect(page.get_by_test_id("wf-save-message")).to_contain_text("Nothing changed live")
    expect(form.locator("[data-field=id]")).to_have_value("ask order")  # the owner's edit is kept
    stored = current(gateway, name)
    assert stored["version"] == 1 and stored["text"] == text
    form.locator("[data-field=id]").fill("ask_for_order")
    expect(page.get_by_test_id("wf-status")).to_have_text("✓ No problems")


def test_a_conflict_is_told_and_the_edits_are_kept(author_page: Page, gateway):
    name, text = copy_workflow(gateway, "7_thanking.yaml")
    page = author_page
    open_workflow(page, name)
    step_button(page, "thank").click()
    field = page.get_by_test_id("wf-form").locator("[data-field='with.text']")
    field.fill("Thank you, see you soon!")
    with gateway.rest(OTHER_AUTHOR_TOKEN) as client:  # bob saves version 2 meanwhile
        response = client.put(f"/api/workflows/{name}", json={
            "text": text.replace("Please come again.", "Come back soon."), "comment": "bob", "base_version": 1})
        assert response.status_code == 201
    expect(page.get_by_test_id("wf-status")).to_have_text("✓ No problems")
    page.get_by_test_id("wf-save").click()
    conflict = page.get_by_test_id("wf-conflict")
    expect(conflict).to_contain_text("someone else saved version 2")
    expect(conflict).to_contain_text("your edits are still here")
    expect(field).to_have_value("Thank you, see you soon!")
    assert current(gateway, name)["version"] == 2
    conflict.get_by_role("button", name="Compare my edits with version 2").click()
    expect(page.get_by_test_id("wf-conflict-diff")).to_contain_text("Come back soon.")
    expect(page.get_by_test_id("wf-conflict-diff")).to_contain_text("Thank you, see you soon!")
    conflict.get_by_role("button", name="Save mine over version 2").click()
    expect(page.get_by_test_id("wf-save-message")).to_contain_text("Saved: version 3 is live")
    assert "Thank you, see you soon!" in current(gateway, name)["text"]


def test_versions_diff_and_rollback(author_page: Page, gateway):
    name, text = copy_workflow(gateway, "7_thanking.yaml")
    page = author_page
    open_workflow(page, name)
    step_button(page, "thank").click()
    page.get_by_test_id("wf-form").locator("[data-field='with.text']").fill("Thanks a lot!")
    save(page, "shorter thanks", 2)
    page.get_by_role("tab", name="Versions").click()
    page.get_by_role("button", name="Compare").click()
    expect(page.get_by_test_id("wf-diff")).to_contain_text("Left: version 1 · right: version 2")
    expect(page.get_by_test_id("wf-diff")).to_contain_text("Thanks a lot!")
    page.get_by_role("button", name="Roll back to version 1").click()
    expect(page.locator(".flash")).to_contain_text("Rolled back: version 1 is live again")
    expect(page.locator("[data-testid=wf-versions] tr.live-row")).to_have_attribute("data-version", "1")
    stored = current(gateway, name)
    assert stored["version"] == 1 and stored["text"] == text
    expect(page.get_by_test_id("wf-version")).to_have_text("version 1 live")


def test_every_teahouse_workflow_opens_without_problems(author_page: Page, gateway):
    with gateway.rest(CALLER_TOKEN) as client:
        names = [w["name"] for w in client.get("/api/workflows").json()]
    page = author_page
    for file in sorted(WORKFLOWS.glob("*.yaml")):
        name = next(line.split(":", 1)[1].strip() for line in file.read_text().splitlines()
                    if line.startswith("workflow:"))
        assert name in names
        open_workflow(page, name)
        expect(page.locator(f".ruleset-list a[data-workflow={name}]")).to_be_visible()
        expect(page.locator("li.wf-step").first).to_be_visible()
    open_workflow(page, "take_order")
    step_button(page, "send_order").click()  # a topic: its parameters as text fields
    expect(page.get_by_test_id("wf-form").locator("[data-field='with.data']")).to_have_value(
        "${input.table.id}: ${order.cups} x ${order.drink}")


def test_an_unknown_workflow_is_said_so_and_discard_can_be_undone(author_page: Page, gateway):
    page = author_page
    page.goto("/workbench/workflows/no_such_workflow")
    expect(page.get_by_role("alert")).to_contain_text("Cannot open the workflow “no_such_workflow”")
    name, _ = copy_workflow(gateway, "7_thanking.yaml")
    open_workflow(page, name)
    step_button(page, "bow").focus()
    page.keyboard.press("Delete")
    page.get_by_role("button", name="Discard changes").click()
    expect(step_button(page, "bow")).to_have_count(1)
    expect(page.locator(".wf-editor .badge.dirty")).to_be_hidden()
    page.get_by_role("button", name="Undo the last change").click()
    expect(step_button(page, "bow")).to_have_count(0)


def test_scenario_view_and_editing_the_yaml_by_hand(author_page: Page, gateway):
    from wb_helpers import replace_text

    name, _ = copy_workflow(gateway, "7_thanking.yaml")
    page = author_page
    open_workflow(page, name)
    page.get_by_role("tab", name="Scenario view").click()
    scenario = page.get_by_test_id("wf-scenario")
    expect(scenario.locator("thead th").nth(1)).to_have_text("Pepper")
    expect(scenario.locator("tbody tr")).to_have_count(4)
    scenario.get_by_role("button", name="say: Thank you very much. Please come again.").click()
    expect(page.get_by_test_id("wf-form").locator("[data-field='with.text']")).to_have_value(
        "Thank you very much. Please come again.")
    page.get_by_role("tab", name="YAML").click()
    replace_text(page, "Please come again.", "Come back soon!")  # for those who want the YAML
    page.get_by_role("tab", name="Process view").click()
    expect(step_button(page, "thank")).to_contain_text("Come back soon!")
    save(page, "edited as YAML", 2)
    assert "Come back soon!" in current(gateway, name)["text"]


def test_yaml_and_generated_python_tabs(author_page: Page, gateway):
    name, _ = copy_workflow(gateway, "7_thanking.yaml")
    page = author_page
    open_workflow(page, name)
    step_button(page, "bow").focus()
    page.keyboard.press("Delete")
    page.get_by_role("tab", name="YAML").click()
    yaml_editor = page.get_by_label("Workflow YAML")
    expect(yaml_editor).not_to_contain_text("id: bow")
    expect(yaml_editor).to_contain_text("id: back_to_counter")
    page.get_by_role("tab", name="Python").click()
    python = page.get_by_label("Generated Python (read-only)")
    expect(python).to_contain_text("rclpy")
    expect(python).to_have_attribute("contenteditable", "false")


def test_the_editor_fits_a_laptop_and_a_tablet(author_page: Page, gateway, screenshots):
    name, _ = copy_workflow(gateway, "4_prepare_drinks.yaml")
    page = author_page
    for width, height in ((1280, 800), (768, 1024)):
        page.set_viewport_size({"width": width, "height": height})
        open_workflow(page, name)
        step_button(page, "carry").click()
        overflow = page.evaluate("document.documentElement.scrollWidth - document.documentElement.clientWidth")
        assert overflow <= 0, f"{width}px: the page scrolls sideways by {overflow}px"
        expect(page.get_by_role("button", name="Add new steps at the end of the else arm of any_order")).to_be_visible()
        page.screenshot(path=str(screenshots / f"workflow-editor-{width}.png"))


def test_a_caller_sees_but_cannot_save(browser, gateway):
    from wb_helpers import new_page

    name, _ = copy_workflow(gateway, "7_thanking.yaml")
    page = new_page(browser, gateway, CALLER_TOKEN)
    try:
        open_workflow(page, name)
        expect(page.get_by_test_id("wf-save")).to_have_count(0)
        expect(page.get_by_text("Only authors may save.")).to_be_visible()
        assert page.js_errors == []
    finally:
        page.context.close()


# ---------------------------------------------------------------- the palette API


def test_palette_is_built_from_what_exists(gateway):
    with gateway.rest(CALLER_TOKEN) as client:
        palette = client.get("/api/workflows/palette").json()
        rulesets = sorted(r["name"] for r in client.get("/api/rulesets").json())
    robots = {r["name"]: r for r in palette["robots"]}
    assert robots["pepper"]["configured"] and set(robots["pepper"]["services"]) == {"speak", "gesture", "move_to"}
    assert not robots["jaco2"]["configured"] and robots["jaco2"]["services"] == {
        "gesture": "printeps_interfaces/srv/Gesture"}  # driven by the prepare_drinks workflow
    entries = {e["id"]: e for e in palette["entries"]}
    say = entries["pepper.speak"]
    assert say["module"]["service"] == "/pepper/speak" and say["module"]["type"] == "printeps_interfaces/srv/Speak"
    params = {p["name"]: p for p in say["params"]}
    assert params["text"] == {"name": "text", "type": "string", "required": True, "description": "What the robot says."}
    assert params["robot"]["type"] == "robot" and "pepper" in params["robot"]["choices"]
    move = {p["name"]: p["type"] for p in entries["pepper.move_to"]["params"]}
    assert move == {"robot": "robot", "location": "string", "x": "number", "y": "number"}
    assert palette["rulesets"] == rulesets and "reception" in rulesets
    ruleset = next(p for p in entries["fire_rules"]["module_params"] if p["name"] == "ruleset")
    assert ruleset["type"] == "ruleset" and ruleset["choices"] == rulesets and ruleset["required"]
    values = {v["name"]: v["value"] for v in palette["ontology_values"]}
    assert float(values["pepper1.robotToHumanDistance"]) > 0
    lookup = next(p for p in entries["ontology_value"]["params"] if p["name"] == "name")
    assert lookup["type"] == "ontology_value" and "pepper1.robotToHumanDistance" in lookup["choices"]
    assert entries["wait"]["module"] == {"kind": "wait", "params": {"seconds": 1}}
    assert entries["branch"]["params"][0]["name"] == "if"
    assert {p["name"] for p in palette["step_params"]} >= {"id", "save", "on_failure"}


def test_validate_takes_the_editors_document(gateway):
    text = (WORKFLOWS / "3_take_order.yaml").read_text(encoding="utf-8")
    with gateway.rest(CALLER_TOKEN) as client:
        document = client.post("/api/workflows/validate", json={"text": text}).json()["document"]
        document["modules"]["pause"] = {"kind": "wait", "params": {"seconds": 0.2}}
        document["processes"]["take_order"]["steps"].insert(1, {"id": "let_them_finish", "module": "pause"})
        good = client.post("/api/workflows/validate", json={"document": document, "previous_text": text}).json()
        assert good["valid"], good["problems"]
        assert good["text"].startswith("# Business process (3)")  # the leading comments are kept
        assert good["text"].index("let_them_finish") < good["text"].index("confirm_order")
        document["processes"]["take_order"]["steps"][1]["with"] = {"seconds": "soon"}
        bad = client.post("/api/workflows/validate", json={"document": document}).json()
        assert not bad["valid"]
        assert [p["path"] for p in bad["problems"]] == ["processes.take_order.steps[1].with.seconds"]
        assert "not a number of seconds" in bad["problems"][0]["message"]
        neither = client.post("/api/workflows/validate", json={})
        assert neither.status_code == 422


def test_version_texts_and_the_shell_serves_the_section(gateway):
    name, text = copy_workflow(gateway, "8_clear_table.yaml")
    with gateway.rest(CALLER_TOKEN) as client:
        assert client.get(f"/api/workflows/{name}/versions/1").json()["text"] == text
        assert client.get(f"/api/workflows/{name}/versions/9").status_code == 404
        page = client.get(f"/workbench/workflows/{name}")
        assert page.status_code == 200 and "/workbench/static/app.js" in page.text


def test_a_running_run_shows_the_steps_done_so_far(gateway):
    name, text = copy_workflow(gateway, "3_take_order.yaml")
    paused = text.replace("  publish_order:", "  pause: {kind: wait, params: {seconds: 2}}\n  publish_order:").replace(
        "      - id: confirm_order\n",
        "      - id: let_them_finish\n        module: pause\n      - id: confirm_order\n")
    with gateway.rest() as client:
        assert client.put(f"/api/workflows/{name}", json={"text": paused, "base_version": 1}).status_code == 201
        run_id = client.post(f"/api/workflows/{name}/run", json={"wait": False}).json()["run_id"]
        seen_while_running: list[list[str]] = []
        for _ in range(600):
            response = client.get(f"/api/workflows/runs/{run_id}")
            if response.status_code == 200:
                break
            assert response.status_code == 202 and response.json()["status"] == "running"
            seen_while_running.append([s["step_id"] for s in response.json()["steps"]])
            time.sleep(0.05)
        assert response.status_code == 200 and response.json()["status"] == "succeeded"
    assert any("ask_order" in steps and "confirm_order" not in steps for steps in seen_while_running)


def test_author_token_is_needed_to_save(gateway):
    name, text = copy_workflow(gateway, "8_clear_table.yaml")
    with gateway.rest(CALLER_TOKEN) as client:
        assert client.put(f"/api/workflows/{name}", json={"text": text, "base_version": 1}).status_code == 403
    with gateway.rest(AUTHOR_TOKEN) as client:
        assert client.put(f"/api/workflows/{name}", json={"text": text + "\n", "base_version": 1}).status_code == 201
