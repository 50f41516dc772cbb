"""Steps a rule author takes in the workbench, as Playwright actions (keyboard and mouse only)."""

from __future__ import annotations

import json

from playwright.sync_api import Page, expect

from gateway.config import PROJECT_ROOT

AUTHOR_TOKEN = "wb-author-token"
OTHER_AUTHOR_TOKEN = "wb-other-author-token"
CALLER_TOKEN = "wb-caller-token"
TOKENS = f"{AUTHOR_TOKEN}:author:alice,{OTHER_AUTHOR_TOKEN}:author:bob,{CALLER_TOKEN}:caller:carol"
RECEPTION = PROJECT_ROOT / "rules" / "drl" / "reception"
GREETINGS = PROJECT_ROOT / "rules" / "drl" / "reception_greetings"


def reception_files() -> dict[str, str]:
    """The teahouse reception rule set's rule files, as the REST API takes it (without its test
    scenarios, so that tests changing what Pepper says can deploy)."""
    return {p.name: p.read_text(encoding="utf-8") for p in sorted(RECEPTION.iterdir()) if p.is_file()}


def folder_files(folder) -> dict[str, str]:
    """A rule set folder with everything in it (tests/*.yaml, workbooks as data: URLs)."""
    from gateway.engine.ruleset import read_folder

    return read_folder(folder)


def new_page(browser, gateway, token: str | None):
    """A page in a fresh context; with ``token`` the user is already signed in."""
    context = browser.new_context(viewport={"width": 1400, "height": 900}, base_url=gateway.base_url)
    context.set_default_timeout(15_000)
    if token:
        context.add_init_script(f"localStorage.setItem('printeps.workbench.token', {token!r})")
    page = context.new_page()
    errors: list[str] = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.js_errors = errors  # checked by the tests: a script error is a failure
    logged: list[str] = []
    page.on("console", lambda msg: logged.append(msg.text) if msg.type == "error" else None)
    page.console_errors = logged  # what the page logs as errors (refused requests included)
    return page


#: How the browser logs a refused request (a 404 probe, a 409 conflict, a 422 check) that a view
#: handles itself: not an error of the page.
REFUSED_REQUEST = "Failed to load resource"


def console_errors(page, allowed: str | None = None) -> list[str]:
    """The page's logged errors, without those starting with ``allowed`` (e.g. :data:`REFUSED_REQUEST`)."""
    return [e for e in page.console_errors if not (allowed and e.startswith(allowed))]

EDITOR = ".editor-host:not([hidden]) .cm-content"


def open_ruleset(page: Page, name: str) -> None:
    page.goto(f"/workbench#/rules/{name}")
    expect(page.locator("[data-testid=check-status]")).to_have_text("✓ No problems")


def replace_text(page: Page, old: str, new: str) -> None:
    """Find ``old`` in the shown editor with the search box (Ctrl+F) and type ``new`` over it."""
    page.locator(EDITOR).click()
    page.keyboard.press("Control+Home")
    page.keyboard.press("Control+f")
    field = page.locator(".editor-host:not([hidden]) .cm-search input[name=search]")
    field.fill(old)
    field.press("End")  # the search box takes its query on key-up, not on input
    field.press("Enter")
    field.press("Escape")
    page.keyboard.type(new)


def choose_tab(page: Page, file_name: str) -> None:
    page.locator(f".tab[data-file='{file_name}']").click()


def try_example(page: Page, example: str) -> None:
    page.get_by_role("button", name=example, exact=True).click()
    page.get_by_test_id("try").click()


def example_facts(files: dict[str, str], name: str) -> list[dict]:
    return next(e["facts"] for e in json.loads(files["examples.json"]) if e["name"] == name)


def said(result: dict) -> list[str]:
    """What Pepper says in a fire result."""
    return [a["params"]["text"] for a in result["actions"] if a["module"] == "say"]


def line_of(text: str, needle: str) -> int:
    """1-based line number of the first line containing ``needle``."""
    return next(i for i, line in enumerate(text.split("\n"), 1) if needle in line)
