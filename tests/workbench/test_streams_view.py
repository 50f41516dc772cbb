"""The Streams section: continuous queries and RDF mappings read, checked, changed, previewed and
rolled back in the browser, against the real gateway (stream engine, catalog in the real Mongo
server). Edit tests use queries and mappings of their own, so the seeded ones stay as they are."""

from __future__ import annotations

import itertools
import os
import re
from collections.abc import Iterator

import pytest
from playwright.sync_api import Page, expect

from wb_helpers import CALLER_TOKEN, REFUSED_REQUEST, new_page
from wb_helpers import console_errors as logged_errors

_ids = itertools.count(1)
STREAM = "http://example.org/wb-streams"
RDF_TYPE = "http://www.w3.org/1999/02/22-rdf-syntax-ns#type"


@pytest.fixture()
def console_errors(author_page) -> Iterator[list[str]]:
    """What the page logs as errors (a failed request included); each test ends with none."""
    yield author_page.console_errors
    assert author_page.console_errors == []


def _unique(stem: str) -> str:
    return f"{stem}{os.getpid()}x{next(_ids)}"


def _count_query(name: str, range_s: int = 2) -> str:
    return (f"REGISTER QUERY {name} AS\n"
            "PREFIX ex: <http://example.org/>\n"
            "SELECT (COUNT(?s) AS ?n)\n"
            f"FROM STREAM <{STREAM}/{name}> [RANGE {range_s}s STEP 1s]\n"
            "WHERE { ?s a ex:Thing . }\n")


def _register(gateway, name: str) -> str:
    text = _count_query(name)
    with gateway.rest() as client:
        r = client.post("/api/queries", json={"query": text, "comment": "made by the test"})
        assert r.status_code == 201, r.text
    return text


def _set_text(page: Page, editor: str, text: str) -> None:
    """Replace the whole text of a CodeMirror editor (as a paste: no auto-closed brackets)."""
    page.locator(f"[data-testid={editor}] .cm-content").click()
    page.keyboard.press("Control+a")
    page.keyboard.insert_text(text)


def _editor_text(page: Page, editor: str) -> str:
    return page.locator(f"[data-testid={editor}] .cm-content").evaluate(
        "el => Array.from(el.querySelectorAll('.cm-line')).map((line) => line.textContent).join('\\n')")


def test_open_the_entrance_mapping_and_the_seeded_query(author_page, gateway, console_errors):
    page = author_page
    page.goto("/workbench#/streams")
    expect(page.locator("main h1")).to_have_text("Streams")
    expect(page.get_by_test_id("mappings")).to_contain_text("printeps_interfaces/msg/Entrance")
    page.get_by_test_id("mapping-link-entrance").click()
    expect(page).to_have_url(re.compile(r"#/streams/mappings/entrance$"))
    expect(page.locator("main h1")).to_have_text("Mapping · entrance")
    expect(page.get_by_test_id("mapping-editor")).to_contain_text("printeps:hasCustomer")
    expect(page.get_by_test_id("mapping-versions").locator("tr.live-row")).to_contain_text("Live now")
    page.get_by_test_id("query-link-CustomerDetectionQuery").click()
    expect(page.locator("main h1")).to_have_text("Query · CustomerDetectionQuery")
    expect(page.get_by_test_id("query-editor")).to_contain_text("REGISTER QUERY CustomerDetectionQuery AS")
    expect(page.get_by_test_id("binding-editor")).to_contain_text('"fact_type": "Customer"')
    expect(page.get_by_test_id("query-versions")).to_contain_text("seeded from customer_detection.rq")
    expect(page.get_by_test_id("query-check")).to_be_visible()
    page.get_by_test_id("query-check").click()
    expect(page.get_by_test_id("check-ok")).to_contain_text("Valid: query CustomerDetectionQuery")


def test_results_show_the_last_windows_with_their_bounds(author_page, gateway, console_errors):
    name = _unique("ViewCount")
    _register(gateway, name)
    with gateway.rest() as client:
        for ts in (500, 1500, 2500, 3500):
            r = client.post("/api/streams", json={"stream": f"{STREAM}/{name}", "timestamp": ts, "triples": [
                [f"http://example.org/t{ts}", RDF_TYPE, "<http://example.org/Thing>"]]})
            assert r.status_code == 200, r.text
    page = author_page
    page.goto(f"/workbench#/streams/queries/{name}")
    table = page.get_by_test_id("query-results").locator("table")
    expect(table.locator("thead")).to_contain_text("Window start")
    expect(table.locator("thead")).to_contain_text("n")
    expect(table.locator("tbody tr").first).to_contain_text("ms")


def test_a_bad_query_shows_its_line_and_column_and_changes_nothing(author_page, gateway, console_errors, screenshots):
    name = _unique("BadEdit")
    original = _register(gateway, name)
    page = author_page
    page.goto(f"/workbench#/streams/queries/{name}")
    expect(page.get_by_test_id("query-editor")).to_contain_text(f"REGISTER QUERY {name}")
    broken = original.replace("WHERE { ?s a ex:Thing . }", "WHERE { ?s a ex:Thing .\n  SERVICE <http://example.org/x> { ?s ?p ?o } }")
    expect(page.get_by_test_id("unsaved")).to_be_hidden()
    _set_text(page, "query-editor", broken)
    expect(page.get_by_test_id("unsaved")).to_be_visible()
    page.get_by_test_id("query-save").click()
    message = page.get_by_test_id("query-message")
    expect(message.get_by_test_id("problem-at")).to_have_text("line 6, column 3")
    expect(message).to_contain_text("SERVICE (federated query) is not supported")
    expect(page.locator("[data-testid=query-editor] .cm-lintRange-error")).to_have_count(1)
    page.screenshot(path=str(screenshots / "streams-query-error.png"))
    assert _editor_text(page, "query-editor") == broken  # the author's text is kept
    expect(page.get_by_test_id("unsaved")).to_be_visible()
    with gateway.rest() as client:
        live = client.get(f"/api/queries/{name}").json()
        assert live["version"] == 1 and live["text"] == original
        assert len(client.get(f"/api/queries/{name}/versions").json()) == 1
    # a rule binding that is not JSON is named as such, nothing sent
    _set_text(page, "query-editor", original)
    _set_text(page, "binding-editor", "{ruleset: reception")
    page.get_by_test_id("query-check").click()
    expect(message).to_contain_text("the rule binding is not JSON")


def test_save_a_copy_then_a_new_version_then_roll_back(author_page, gateway, console_errors):
    name = _unique("EditMe")
    original = _register(gateway, name)
    copy = _unique("EditCopy")
    page = author_page
    page.goto(f"/workbench#/streams/queries/{name}")
    expect(page.get_by_test_id("query-version")).to_have_text("version 1 live")
    _set_text(page, "query-editor", original.replace(f"REGISTER QUERY {name}", f"REGISTER QUERY {copy}"))
    page.get_by_test_id("query-check").click()
    expect(page.get_by_test_id("check-ok")).to_contain_text(f"registers it as a new query {copy}")
    page.get_by_test_id("query-comment").fill("a copy")
    page.get_by_test_id("query-save").click()
    expect(page.locator("main h1")).to_have_text(f"Query · {copy}")
    expect(page.get_by_test_id(f"query-link-{copy}")).to_be_visible()
    expect(page.get_by_test_id("query-version")).to_have_text("version 1 live")
    # a new version of the copy: a wider window, with a comment
    _set_text(page, "query-editor", _editor_text(page, "query-editor").replace("RANGE 2s", "RANGE 5s"))
    page.get_by_test_id("query-comment").fill("wider window")
    page.get_by_test_id("query-save").click()
    expect(page.get_by_test_id("query-version")).to_have_text("version 2 live")
    versions = page.get_by_test_id("query-versions")
    expect(versions.locator("tbody tr")).to_have_count(2)
    expect(versions.locator("tr.live-row")).to_contain_text("wider window")
    with gateway.rest() as client:
        assert client.get(f"/api/queries/{copy}").json()["windows"][0]["range_ms"] == 5000
        assert client.get(f"/api/queries/{name}").json()["version"] == 1  # the original is untouched
    page.get_by_test_id("rollback-1").click()
    page.get_by_test_id("confirm-rollback-1").click()
    expect(page.get_by_test_id("query-version")).to_have_text("version 1 live")
    expect(page.locator(".flash")).to_contain_text("Rolled back")
    with gateway.rest() as client:
        assert client.get(f"/api/queries/{copy}").json()["windows"][0]["range_ms"] == 2000


def test_a_mapping_is_previewed_saved_as_a_copy_versioned_and_rolled_back(author_page, gateway, console_errors,
                                                                          screenshots):
    page = author_page
    page.goto("/workbench#/streams/mappings/entrance")
    expect(page.get_by_test_id("mapping-editor")).to_contain_text("printeps:hasCustomer")
    page.get_by_test_id("mapping-preview").click()  # the sample message made from the mapping itself
    triples = page.get_by_test_id("triples")
    expect(triples).to_contain_text("printeps:hasCustomer")
    expect(triples).to_contain_text("printeps:distance")
    expect(triples).to_contain_text("rdf:type")
    page.screenshot(path=str(screenshots / "streams-mapping-preview.png"))
    copy = _unique("entrance_copy")
    page.get_by_test_id("mapping-name").fill(copy)
    page.get_by_test_id("mapping-comment").fill("a copy to play with")
    page.get_by_test_id("mapping-save").click()
    expect(page.locator("main h1")).to_have_text(f"Mapping · {copy}")
    expect(page.get_by_test_id("mapping-version")).to_have_text("version 1 live")
    # a bad key is shown at its line; nothing is saved and the text stays
    text = _editor_text(page, "mapping-editor")
    broken = text.replace("link: printeps:hasCustomer", "lnk: printeps:hasCustomer")
    _set_text(page, "mapping-editor", broken)
    page.get_by_test_id("mapping-save").click()
    message = page.get_by_test_id("mapping-message")
    expect(message).to_contain_text("mapping.children.customers")
    expect(message.get_by_test_id("problem-at")).to_have_text(re.compile(r"line \d+, column \d+"))
    expect(page.locator("[data-testid=mapping-editor] .cm-lintRange-error")).to_have_count(1)
    assert _editor_text(page, "mapping-editor") == broken
    with gateway.rest() as client:
        assert client.get(f"/api/mappings/{copy}").json()["version"] == 1
    # the preview follows the text being edited; then save it as version 2
    _set_text(page, "mapping-editor", text.replace("gender: printeps:gender", "gender: printeps:sex"))
    page.get_by_test_id("mapping-validate").click()
    expect(page.get_by_test_id("validate-ok")).to_be_visible()
    page.get_by_test_id("mapping-preview").click()
    expect(triples).to_contain_text("printeps:sex")
    page.get_by_test_id("mapping-comment").fill("sex, not gender")
    page.get_by_test_id("mapping-save").click()
    expect(page.get_by_test_id("mapping-version")).to_have_text("version 2 live")
    expect(page.get_by_test_id("mapping-versions").locator("tbody tr")).to_have_count(2)
    page.get_by_test_id("rollback-1").click()
    page.get_by_test_id("confirm-rollback-1").click()
    expect(page.get_by_test_id("mapping-version")).to_have_text("version 1 live")
    expect(page.get_by_test_id("mapping-editor")).to_contain_text("printeps:gender")
    with gateway.rest() as client:
        assert client.get("/api/mappings/entrance").json()["version"] == 1  # the seeded one is untouched


def test_a_save_over_a_newer_version_is_refused_and_keeps_the_text(author_page, gateway):
    name = _unique("Race")
    original = _register(gateway, name)
    page = author_page
    page.goto(f"/workbench#/streams/queries/{name}")
    expect(page.get_by_test_id("query-version")).to_have_text("version 1 live")
    with gateway.rest() as client:  # another author saves version 2 meanwhile
        r = client.post("/api/queries", json={"query": original.replace("RANGE 2s", "RANGE 3s"), "replace": True,
                                              "base_version": 1, "comment": "someone else"})
        assert r.status_code == 201, r.text
    mine = original.replace("RANGE 2s", "RANGE 9s")
    _set_text(page, "query-editor", mine)
    page.get_by_test_id("query-save").click()
    expect(page.get_by_test_id("conflict")).to_contain_text("someone saved version 2 of this query")
    assert _editor_text(page, "query-editor") == mine
    with gateway.rest() as client:
        assert client.get(f"/api/queries/{name}").json()["windows"][0]["range_ms"] == 3000


def test_new_query_and_new_mapping_from_the_templates(author_page, gateway, console_errors):
    page = author_page
    page.goto("/workbench#/streams")
    page.get_by_test_id("new-query").click()
    expect(page.locator("main h1")).to_have_text("New query")
    name = _unique("Fresh")
    _set_text(page, "query-editor", _editor_text(page, "query-editor").replace("CustomersNow", name))
    page.get_by_test_id("query-check").click()
    expect(page.get_by_test_id("check-ok")).to_contain_text(f"Save registers it as query {name}")
    page.get_by_test_id("query-save").click()
    expect(page.locator("main h1")).to_have_text(f"Query · {name}")
    expect(page.get_by_test_id("query-version")).to_have_text("version 1 live")
    page.goto("/workbench#/streams/new/mapping")
    expect(page.locator("main h1")).to_have_text("New mapping")
    page.get_by_test_id("mapping-preview").click()
    expect(page.get_by_test_id("triples")).to_contain_text("printeps:reading_1")
    page.get_by_test_id("mapping-save").click()  # no name yet: refused, nothing sent
    expect(page.get_by_test_id("mapping-message")).to_contain_text("the name must start with a letter")
    mapping = _unique("fresh_mapping")
    page.get_by_test_id("mapping-name").fill(mapping)
    page.get_by_test_id("mapping-save").click()
    expect(page.locator("main h1")).to_have_text(f"Mapping · {mapping}")
    expect(page.get_by_test_id("mapping-version")).to_have_text("version 1 live")
    with gateway.rest() as client:
        assert client.get(f"/api/mappings/{mapping}").json()["spec"]["type"] == "printeps:Reading"


def test_a_path_deep_link_opens_a_mapping(author_page, console_errors):
    page = author_page
    page.goto("/workbench/streams/mappings/entrance")
    expect(page).to_have_url(re.compile(r"/workbench#/streams/mappings/entrance$"))
    expect(page.locator("main h1")).to_have_text("Mapping · entrance")
    page.goto("/workbench/streams/queries/CustomerDetectionQuery")
    expect(page.locator("main h1")).to_have_text("Query · CustomerDetectionQuery")


def test_callers_see_read_only_pages(browser, gateway):
    page = new_page(browser, gateway, CALLER_TOKEN)
    page.goto("/workbench#/streams/queries/CustomerDetectionQuery")
    expect(page.get_by_test_id("read-only")).to_be_visible()
    expect(page.locator("[data-testid=query-editor] .cm-content")).to_have_attribute("contenteditable", "false")
    expect(page.get_by_test_id("query-save")).to_have_count(0)
    expect(page.get_by_test_id("rollback-1")).to_have_count(0)
    page.goto("/workbench#/streams/mappings/entrance")
    expect(page.get_by_test_id("read-only")).to_be_visible()
    expect(page.get_by_test_id("mapping-save")).to_have_count(0)
    page.get_by_test_id("mapping-preview").click()  # previewing changes nothing: callers may
    expect(page.get_by_test_id("triples")).to_contain_text("hasCustomer")
    page.goto("/workbench#/streams")
    expect(page.locator("main h1")).to_have_text("Streams")
    expect(page.get_by_test_id("new-query")).to_have_count(0)
    page.goto("/workbench#/streams/new/query")
    expect(page.locator("main")).to_contain_text("Only authors can add queries")
    page.context.close()
    assert page.js_errors == [] and page.console_errors == []


def test_tablet_width_keeps_the_pages_on_screen(author_page, console_errors):
    page = author_page
    page.set_viewport_size({"width": 768, "height": 1024})
    for address, ready in (("/workbench#/streams/queries/CustomerDetectionQuery", "query-versions"),
                           ("/workbench#/streams/mappings/entrance", "mapping-versions")):
        page.goto(address)
        expect(page.get_by_test_id(ready)).to_be_visible()
        if "mappings" in address:
            page.get_by_test_id("mapping-preview").click()
            expect(page.get_by_test_id("triples")).to_be_visible()
        width = page.evaluate("document.documentElement.scrollWidth")
        assert width <= 768, f"{address} scrolls sideways at tablet width ({width} px)"


def test_diff_an_older_version_with_the_live_one(author_page, gateway, console_errors, screenshots):
    name = _unique("DiffMe")
    original = _register(gateway, name)
    with gateway.rest() as client:  # version 2: a wider window
        r = client.post("/api/queries", json={"query": original.replace("RANGE 2s", "RANGE 7s"), "replace": True,
                                              "base_version": 1, "comment": "wider"})
        assert r.status_code == 201, r.text
    page = author_page
    page.goto(f"/workbench#/streams/queries/{name}")
    expect(page.get_by_test_id("query-version")).to_have_text("version 2 live")
    expect(page.get_by_test_id("diff-2")).to_have_count(0)  # the live version has nothing to compare with
    page.get_by_test_id("diff-1").click()
    diff = page.get_by_test_id("version-diff")
    expect(diff).to_contain_text("Version 1 (left) → live version 2 (right)")
    expect(diff.locator(".cm-changedLine").first).to_be_visible()
    expect(diff.locator(".cm-changedLine").filter(has_text="RANGE 2s")).to_have_count(1)
    expect(diff.locator(".cm-changedLine").filter(has_text="RANGE 7s")).to_have_count(1)
    page.screenshot(path=str(screenshots / "streams-query-diff.png"))


def test_diff_a_mapping_version(author_page, gateway, console_errors):
    name = _unique("diff_mapping")
    with gateway.rest() as client:
        for version, predicate in ((1, "printeps:value"), (2, "printeps:reading")):
            r = client.put(f"/api/mappings/{name}", json={"text": f"subject: \"printeps:r_{{id}}\"\nfields:\n  value: {predicate}\n",
                                                          "base_version": version - 1})
            assert r.status_code == 201, r.text
    page = author_page
    page.goto(f"/workbench#/streams/mappings/{name}")
    expect(page.get_by_test_id("mapping-version")).to_have_text("version 2 live")
    page.get_by_test_id("diff-1").click()
    changed = page.get_by_test_id("version-diff").locator(".cm-changedLine")
    expect(changed.filter(has_text="printeps:value")).to_have_count(1)
    expect(changed.filter(has_text="printeps:reading")).to_have_count(1)


def test_delete_a_query_after_a_confirmation(author_page, gateway, console_errors, screenshots):
    name = _unique("DeleteMe")
    _register(gateway, name)
    page = author_page
    page.goto(f"/workbench#/streams/queries/{name}")
    expect(page.get_by_test_id(f"query-link-{name}")).to_be_visible()
    page.get_by_test_id("delete").click()  # asks first; Cancel keeps it
    page.get_by_test_id("cancel-delete").click()
    expect(page.get_by_test_id("confirm-delete")).to_have_count(0)
    with gateway.rest() as client:
        assert client.get(f"/api/queries/{name}").status_code == 200
    page.get_by_test_id("delete").click()
    page.screenshot(path=str(screenshots / "streams-query-delete.png"))
    page.get_by_test_id("confirm-delete").click()
    expect(page.get_by_test_id("deleted")).to_contain_text(f"The query {name} is deleted")
    expect(page.get_by_test_id(f"query-link-{name}")).to_have_count(0)
    with gateway.rest() as client:
        assert client.get(f"/api/queries/{name}").status_code == 404
    page.get_by_role("link", name="All queries and mappings").click()
    expect(page.get_by_test_id("queries")).not_to_contain_text(name)


def test_delete_a_mapping_and_a_refused_delete_shows_the_server_error(author_page, gateway):
    name = _unique("delete_mapping")
    with gateway.rest() as client:
        r = client.put(f"/api/mappings/{name}", json={"text": NEW_MAPPING_TEXT, "base_version": 0})
        assert r.status_code == 201, r.text
    page = author_page
    page.goto(f"/workbench#/streams/mappings/{name}")
    expect(page.get_by_test_id("mapping-version")).to_have_text("version 1 live")
    with gateway.rest() as client:  # someone else deletes it first: this delete is refused
        assert client.delete(f"/api/mappings/{name}").status_code == 200
    page.get_by_test_id("delete").click()
    page.get_by_test_id("confirm-delete").click()
    expect(page.get_by_test_id("delete-error")).to_contain_text("Not deleted: ")
    expect(page.get_by_test_id("delete-error")).to_contain_text(name)
    # stored again, now the delete goes through
    with gateway.rest() as client:
        r = client.put(f"/api/mappings/{name}", json={"text": NEW_MAPPING_TEXT, "base_version": 0})
        assert r.status_code == 201, r.text
    page.reload()
    expect(page.get_by_test_id("mapping-version")).to_be_visible()
    page.get_by_test_id("delete").click()
    page.get_by_test_id("confirm-delete").click()
    expect(page.get_by_test_id("deleted")).to_contain_text(f"The mapping {name} is deleted")
    expect(page.get_by_test_id(f"mapping-link-{name}")).to_have_count(0)
    with gateway.rest() as client:
        assert client.get(f"/api/mappings/{name}").status_code == 404
    # the refused DELETE is logged as a failed request; nothing else is
    assert logged_errors(page, REFUSED_REQUEST) == []


NEW_MAPPING_TEXT = 'subject: "printeps:reading_{id}"\nfields:\n  value: printeps:value\n'


def test_callers_see_no_delete_but_may_diff(browser, gateway):
    name = _unique("ReadOnlyDiff")
    original = _register(gateway, name)
    with gateway.rest() as client:
        r = client.post("/api/queries", json={"query": original.replace("RANGE 2s", "RANGE 4s"), "replace": True,
                                              "base_version": 1})
        assert r.status_code == 201, r.text
    page = new_page(browser, gateway, CALLER_TOKEN)
    page.goto(f"/workbench#/streams/queries/{name}")
    expect(page.get_by_test_id("read-only")).to_be_visible()
    expect(page.get_by_test_id("query-version")).to_have_text("version 2 live")
    expect(page.get_by_test_id("delete")).to_have_count(0)
    page.get_by_test_id("diff-1").click()
    expect(page.get_by_test_id("version-diff").locator(".cm-changedLine").filter(has_text="RANGE 4s")).to_have_count(1)
    page.goto("/workbench#/streams/mappings/entrance")
    expect(page.get_by_test_id("read-only")).to_be_visible()
    expect(page.get_by_test_id("delete")).to_have_count(0)
    page.context.close()
    assert page.js_errors == [] and page.console_errors == []
