"""The workbench page in a real browser: workflow view, scenario view, editing with validation, running."""

from __future__ import annotations

import pytest

playwright_api = pytest.importorskip("playwright.sync_api")

from gateway.config import Settings  # noqa: E402
from gw_testing import built_gateway  # noqa: E402

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def base_url(tmp_path_factory, mongo):
    from gateway.serve import free_port, serve_in_thread

    tmp = tmp_path_factory.mktemp("wfweb")
    settings = Settings.model_validate({
        "data_dir": str(tmp / "var"), "engine": {"rules_dir": str(tmp / "rules")},
        "workflows": {"simulate_robots": True, "simulate_humans": True}, "streams": {"queries_dir": None},
    })
    with built_gateway(settings, mongo, tmp) as gateway:
        server, thread = serve_in_thread(gateway.app, free_port())
        yield f"http://127.0.0.1:{server.config.port}"
        server.should_exit = True
        thread.join(timeout=10)


@pytest.fixture(scope="module")
def page(browser, base_url):
    context = browser.new_context()
    page = context.new_page()
    page.set_default_timeout(15_000)
    yield page
    context.close()


def test_views_edit_and_run(page, base_url):
    page.goto(f"{base_url}/workbench/workflows#thanking")
    page.wait_for_selector("#list button[data-name=thanking]")
    page.wait_for_selector("#workflow-view g.box[data-step=thank]")
    assert page.locator("#list button").count() == 8
    assert "Thank you very much" in page.locator("#workflow-view g.box[data-step=thank] title").text_content()
    page.click("[data-tab=scenario]")
    lanes = page.locator("#scenario-view text.heading").all_text_contents()
    assert lanes[0] == "Pepper"
    assert page.locator("#scenario-view g.box").count() == 4

    page.click("[data-tab=edit]")
    text = page.input_value("#editor")
    page.fill("#editor", text.replace("module: say", "module: sing"))
    page.click("#validate")
    problem = page.wait_for_selector("#problems li").text_content()
    assert "processes.see_off.steps[1].module: unknown module 'sing'" in problem and problem.startswith("line ")
    page.fill("#editor", text.replace("Please come again.", "Come back soon!"))
    page.fill("#comment", "owner's wording")
    page.click("#save")
    page.wait_for_selector("#problems li.ok >> text=is live")
    assert "owner's wording" in page.text_content("#meta")

    page.click("[data-tab=run]")
    page.click("#run")
    page.wait_for_selector("#trace tbody tr >> nth=3")
    rows = page.locator("#trace tbody tr").all_text_contents()
    assert any("Come back soon!" in row for row in rows) and all("ok" in row for row in rows)
