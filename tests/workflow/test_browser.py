"""The workbench page in a real browser: workflow view, scenario view, editing with validation, running."""

from __future__ import annotations

import socket
import threading
import time

import pytest

playwright_api = pytest.importorskip("playwright.sync_api")

from gateway.api.app import create_app  # noqa: E402
from gateway.config import PROJECT_ROOT, Settings  # noqa: E402
from gateway.engine import Engine  # noqa: E402

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def base_url(tmp_path_factory):
    import uvicorn

    tmp = tmp_path_factory.mktemp("wfweb")
    settings = Settings.model_validate({
        "data_dir": str(tmp / "var"), "engine": {"rules_dir": str(tmp / "rules")},
        "workflows": {"simulate_robots": True, "simulate_humans": True},
    })
    app = create_app(settings, Engine(settings))
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 20
    while not server.started and time.monotonic() < deadline:
        time.sleep(0.05)
    assert server.started
    yield f"http://127.0.0.1:{port}"
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
    assert page.locator("#list button").count() == 7
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
