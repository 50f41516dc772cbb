"""Rule authoring help in the workbench, in a real browser against the real gateway: DSL completion
with tab stops, hover, quick fixes for misspelt sentences, the Tests view, and the decision-table
grid (issue 16)."""

from __future__ import annotations

import itertools
import os

import pytest
from playwright.sync_api import expect

from wb_helpers import EDITOR, GREETINGS, RECEPTION, choose_tab, folder_files, open_ruleset, replace_text, said

pytestmark = pytest.mark.browser
expect.set_options(timeout=20_000)  # a check compiles the rule set: slow on a busy 2-core machine

_names = itertools.count(1)
COMPLETIONS = ".cm-tooltip-autocomplete"


_copies: list[str] = []


@pytest.fixture(scope="module", autouse=True)
def _delete_copies(gateway):
    """The copies this file deployed are deleted afterwards: the worker's gateway is shared with
    the other browser files, whose menus and rule lists should not show them."""
    yield
    with gateway.rest() as client:
        for name in _copies:
            response = client.delete(f"/api/rulesets/{name}")
            assert response.status_code == 200, response.text
    _copies.clear()


def deploy_copy(gateway, files: dict[str, str], stem: str) -> str:
    name = f"{stem}-{os.getpid()}-{next(_names)}"
    response = gateway.deploy(name, files, f"copy for a test ({stem})")
    assert response.status_code == 201, response.text
    _copies.append(name)
    return name


def line_end(page, text: str) -> None:
    """Put the caret at the end of the first line containing ``text`` (via the search box)."""
    replace_text(page, text, text)


def test_completion_offers_sentences_with_tab_stops_and_hover_shows_drl(author_page, ruleset, screenshots):
    page = author_page
    open_ruleset(page, ruleset)

    # In a then-part: an action sentence, inserted with its placeholder selected.
    line_end(page, 'Pepper says "Welcome. Two seats?"')
    page.keyboard.press("Enter")
    page.keyboard.type("Pepper sa")
    completions = page.locator(COMPLETIONS)
    expect(completions).to_contain_text('Pepper says "{text}"')
    expect(completions).not_to_contain_text("There is a party at the entrance")  # a condition
    page.screenshot(path=str(screenshots / "workbench-completion.png"))
    completions.locator("li", has_text='Pepper says "{text}"').click()
    page.keyboard.type("Enjoy your tea")  # replaces the selected placeholder
    expect(page.locator(f"{EDITOR} .cm-activeLine")).to_have_text('    Pepper says "Enjoy your tea"')

    # In a when-part: a constraint sentence with two tab stops.
    line_end(page, "- aged between 4 and 12")
    page.keyboard.press("Enter")
    page.keyboard.type("- of betw")
    expect(completions).to_contain_text("- of between {min} and {max} customers")
    expect(completions).not_to_contain_text("Pepper says")  # an action
    completions.locator("li", has_text="- of between {min} and {max} customers").click()
    page.keyboard.type("2")
    page.keyboard.press("Tab")
    page.keyboard.type("5")
    expect(page.locator(f"{EDITOR} .cm-activeLine")).to_have_text("    - of between 2 and 5 customers")
    page.keyboard.press("Control+Shift+k")  # delete that line again: Customers have no number_of_customers
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")

    # Hovering a sentence shows the DRL it stands for, with the line's values.
    page.locator(f"{EDITOR} .cm-line", has_text="- aged between 13 and 19").hover(position={"x": 90, "y": 8})
    hover = page.get_by_test_id("dsl-hover")
    expect(hover).to_contain_text("age >= 13, age <= 19")
    expect(hover).to_contain_text("Adds to the fact on the line above")
    expect(hover).to_contain_text("$c: Customer(category == null, age >= 13, age <= 19)")
    page.screenshot(path=str(screenshots / "workbench-hover.png"))

    # DRL: fact types and, inside a pattern, their fields complete from the declared types.
    choose_tab(page, "types.drl")
    page.locator(EDITOR).click()
    page.keyboard.press("Control+End")
    page.keyboard.type('\nrule "Typed"\nwhen\n    $c: Cust')
    expect(completions).to_contain_text("Customer")
    completions.locator("li", has_text="Customer").first.click()
    page.keyboard.type("(ag")
    expect(completions.locator("li").first).to_contain_text("age")
    expect(completions).to_contain_text("int")
    completions.locator("li", has_text="age").first.click()
    expect(page.locator(f"{EDITOR} .cm-activeLine")).to_contain_text("$c: Customer(age")


def test_quick_fix_corrects_a_misspelt_sentence(author_page, ruleset, screenshots):
    page = author_page
    open_ruleset(page, ruleset)
    replace_text(page, 'Pepper says "Welcome. Two seats?"', 'Pepper sayz "Welcome, you two!"')
    problem = page.get_by_test_id("problems").locator("li")
    expect(problem.first).to_contain_text("no DSL sentence matches")
    marked = page.locator(f"{EDITOR} .cm-lintRange-error, {EDITOR} .cm-lintRange-warning").first
    expect(marked).to_have_text('Pepper sayz "Welcome, you two!"')
    marked.hover()
    fix = page.locator(".cm-diagnosticAction", has_text='Pepper says "Welcome, you two!"')
    expect(fix).to_be_visible()
    page.screenshot(path=str(screenshots / "workbench-quickfix.png"))
    fix.click()
    expect(page.locator(EDITOR)).to_contain_text('Pepper says "Welcome, you two!"')
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")


def test_tests_view_green_then_an_edit_turns_one_red_and_the_deploy_is_refused(author_page, gateway, screenshots):
    page = author_page
    name = deploy_copy(gateway, folder_files(RECEPTION), "reception-tests")
    open_ruleset(page, name)
    expect(page.locator(".tab[data-file='tests/reception.yaml']")).to_contain_text("tests")

    page.get_by_test_id("run-tests").click()
    summary = page.get_by_test_id("tests-summary")
    expect(summary).to_have_text("✓ All 24 scenarios pass")
    expect(page.get_by_test_id("tests").locator("li[data-status=passed]")).to_have_count(24)
    expect(page.get_by_test_id("coverage")).to_contain_text("Every rule (32) is fired by a scenario")

    replace_text(page, 'Pepper says "Welcome. Two seats?"', 'Pepper says "Hi, you two"')
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")
    page.get_by_test_id("run-tests").click()
    expect(summary).to_have_text("✗ 3 of 24 scenarios fail")
    red = page.get_by_test_id("tests").locator("li[data-status=failed]").filter(has_text="the papers' greeting")
    expect(red).to_contain_text('expected action say {robot: pepper, text: "Welcome. Two seats?"} was not requested')
    expect(red.locator(".compare-cols")).to_contain_text("Expected")
    expect(red.locator(".compare-cols")).to_contain_text("pepper says Hi, you two")  # the actual
    red.scroll_into_view_if_needed()
    page.screenshot(path=str(screenshots / "workbench-tests.png"))

    # A red rule set is not deployed, unless the author insists.
    page.get_by_test_id("deploy").click()
    refused = page.get_by_test_id("red-scenarios")
    expect(refused).to_contain_text("Not deployed: 3 test scenarios fail")
    assert "Welcome. Two seats?" in said(gateway.fire(name, example_pair()))
    page.get_by_test_id("deploy-anyway").click()
    expect(page.get_by_test_id("deploy-result")).to_contain_text("Version 2 is now live")
    assert "Hi, you two" in said(gateway.fire(name, example_pair()))


def example_pair() -> list[dict]:
    return [{"type": "Entrance", "id": "entrance", "number_of_customers": 2},
            {"type": "Customer", "id": "c1", "entrance": "entrance", "age": 30, "gender": "female"},
            {"type": "Customer", "id": "c2", "entrance": "entrance", "age": 31, "gender": "female"},
            {"type": "Robot", "id": "pepper", "position": "entrance"}]


def cell(page, ref: str):
    return page.locator(f"[data-testid=grid] input[data-cell='{ref}']")


def test_the_grid_edits_a_decision_table_and_the_change_fires(author_page, gateway, screenshots):
    page = author_page
    name = deploy_copy(gateway, folder_files(GREETINGS), "greetings")
    pair = [{"type": "Group", "entrance": "entrance", "kind": "pair", "size": 2}]
    assert said(gateway.fire(name, pair)) == ["Welcome. Two seats?"]

    open_ruleset(page, name)
    expect(page.locator(".tab[aria-selected=true]")).to_have_attribute("data-file", "greetings.xlsx")
    expect(cell(page, "B13")).to_have_value("Greet a pair")
    expect(cell(page, "F13")).to_have_value("Welcome. Two seats?")
    expect(cell(page, "D8")).to_be_disabled()  # part of the merged object-type cell C8:E8

    # Edit what Pepper says to a pair: checked, tried, deployed, fired.
    cell(page, "F13").fill("Welcome! A cosy table for two?")
    expect(page.get_by_test_id("grid-status")).to_contain_text("Saved in the file")
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")
    page.get_by_role("button", name="pair", exact=True).click()
    page.get_by_test_id("try").click()
    expect(page.get_by_test_id("actions")).to_contain_text("pepper says Welcome! A cosy table for two?")

    # A new row is a new rule; a bad cell is marked where it is.
    cell(page, "B24").click()
    page.get_by_test_id("grid-add-row").click()
    for ref, value in (("B25", "Greet regulars"), ("C25", "regulars"), ("F25", "Welcome back, friends!"),
                       ("J25", "high"), ("K25", "greeting")):
        cell(page, ref).fill(value)
    problem = page.get_by_test_id("problems").locator("li", has_text="greetings.xlsx, cell Greetings!J25")
    expect(problem).to_contain_text("PRIORITY must be a whole number")
    expect(page.locator("[data-testid=grid] td[data-cell='J25'].problem")).to_have_count(1)
    page.screenshot(path=str(screenshots / "workbench-grid.png"))
    cell(page, "J25").fill("20")
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")

    # The DRL preview shows what the table becomes.
    page.get_by_text("Show the DRL it becomes").click()
    expect(page.get_by_test_id("preview")).to_contain_text('rule "Greet regulars"')

    # The table's scenarios guard the deploy: the pair's greeting is pinned by one of them.
    page.get_by_label("What did you change?").fill("Cosier pair greeting, a greeting for regulars")
    page.get_by_test_id("deploy").click()
    expect(page.get_by_test_id("red-scenarios")).to_contain_text("a pair is offered two seats")
    choose_tab(page, "tests/greetings.yaml")
    replace_text(page, 'text: "Welcome. Two seats?"', 'text: "Welcome! A cosy table for two?"')
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")
    page.get_by_test_id("deploy").click()
    expect(page.get_by_test_id("deploy-result")).to_contain_text("Version 2 is now live")
    assert said(gateway.fire(name, pair)) == ["Welcome! A cosy table for two?"]
    regulars = [{"type": "Group", "entrance": "entrance", "kind": "regulars", "size": 4}]
    assert said(gateway.fire(name, regulars)) == ["Welcome back, friends!"]

    # The history compares the table's cells, not the workbook's bytes.
    page.get_by_role("link", name="History").click()
    diff = page.get_by_test_id("diff")
    expect(diff).to_contain_text("greetings.xlsx")
    expect(diff).to_contain_text("13 |  | Greet a pair | pair |  |  | Welcome! A cosy table for two?")


def test_a_spreadsheet_from_the_desktop_becomes_a_decision_table_of_the_rule_set(author_page, gateway, tmp_path):
    page = author_page
    files = {k: v for k, v in folder_files(GREETINGS).items() if not k.endswith(".xlsx") and not k.startswith("tests/")}
    name = deploy_copy(gateway, files, "upload")
    pair = [{"type": "Group", "entrance": "entrance", "kind": "pair", "size": 2}]
    assert said(gateway.fire(name, pair)) == []
    open_ruleset(page, name)
    picker = page.get_by_test_id("add-file")

    # A file of the wrong kind, or one the rule set already has, is refused and adds nothing.
    notes = tmp_path / "notes.txt"
    notes.write_text("not rules", encoding="utf-8")
    picker.set_input_files(str(notes))
    expect(page.get_by_test_id("add-file-result")).to_contain_text("notes.txt: only .xlsx, .csv")
    clash = tmp_path / "types.drl"
    clash.write_text("package x;", encoding="utf-8")
    picker.set_input_files(str(clash))
    expect(page.get_by_test_id("add-file-result")).to_contain_text("already has a file of that name")
    expect(page.locator(".tab")).to_have_count(len(files))

    # The owner's workbook opens as a grid, is checked, and deploys with the rule set.
    picker.set_input_files(str(GREETINGS / "greetings.xlsx"))
    expect(page.get_by_test_id("add-file-result")).to_contain_text("Added greetings.xlsx")
    expect(page.locator(".tab[aria-selected=true]")).to_have_attribute("data-file", "greetings.xlsx")
    expect(cell(page, "F13")).to_have_value("Welcome. Two seats?")
    expect(page.get_by_test_id("check-status")).to_have_text("✓ No problems")
    page.get_by_label("What did you change?").fill("Greetings table from the owner's spreadsheet")
    page.get_by_test_id("deploy").click()
    expect(page.get_by_test_id("deploy-result")).to_contain_text("Version 2 is now live")
    assert said(gateway.fire(name, pair)) == ["Welcome. Two seats?"]
