"""The router that serves the page and its bundled assets (no engine needed)."""

from __future__ import annotations

from fastapi import FastAPI
from fastapi.testclient import TestClient

from gateway.workbench.router import STATIC_DIR, router

client = TestClient(FastAPI(routes=router.routes), follow_redirects=False)


def test_page_and_assets_are_served_from_the_package():
    page = client.get("/workbench")
    assert page.status_code == 200
    assert page.headers["content-type"].startswith("text/html")
    assert "/workbench/static/app.js" in page.text
    script = client.get("/workbench/static/app.js")
    assert script.status_code == 200 and "javascript" in script.headers["content-type"]
    assert client.get("/workbench/static/app.css").status_code == 200
    assert script.headers["cache-control"] == "no-cache"


def test_the_bundle_is_committed_and_has_no_remote_urls():
    bundle = (STATIC_DIR / "app.js").read_text(encoding="utf-8")
    assert "CodeMirror" in bundle or "cm-editor" in bundle
    html = (STATIC_DIR / "index.html").read_text(encoding="utf-8")
    assert "http://" not in html and "https://" not in html


def test_paths_outside_the_static_folder_are_refused():
    for path in ("/workbench/static/../router.py", "/workbench/static/%2e%2e/router.py",
                 "/workbench/static/..%2frouter.py", "/workbench/static/", "/workbench/static/nope.js"):
        response = client.get(path)
        assert response.status_code == 404, path


def test_trailing_slash_goes_to_the_page():
    response = client.get("/workbench/")
    assert response.status_code == 308 and response.headers["location"] == "/workbench"


def test_sections_and_items_have_deep_links_to_the_one_page():
    for path in ("/workbench/workflows", "/workbench/workflows/show_to_seat", "/workbench/knowledge",
                 "/workbench/streams", "/workbench/streams/mappings/entrance",
                 "/workbench/live", "/workbench/decisions/abc-123", "/workbench/rules/reception"):
        response = client.get(path)
        assert response.status_code == 200, path
        assert "/workbench/static/app.js" in response.text


def test_unknown_sections_name_the_sections():
    response = client.get("/workbench/nowhere/x")
    assert response.status_code == 404
    assert "workflows" in response.json()["detail"]
