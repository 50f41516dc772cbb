"""GET /api/state/{collection} over a real store (the router alone, in a bare FastAPI app)."""

from __future__ import annotations

from fastapi import FastAPI
from fastapi.testclient import TestClient

from types import SimpleNamespace

from gateway.api.auth import Authenticator
from gateway.api.errors import install_error_handlers
from gateway.api.routes.state import router
from gateway.config import ApiSettings


def make_client(store) -> TestClient:
    app = FastAPI()
    app.include_router(router)
    install_error_handlers(app)
    app.state.gateway = SimpleNamespace(store=store)
    app.state.auth = Authenticator(ApiSettings())
    return TestClient(app)


def test_filters_type_and_fields(store) -> None:
    store.record("actions", {"robot": "pepper", "seats": 2}, stored_type="printeps/Action")
    store.record("actions", {"robot": "hsr", "seats": 3}, stored_type="printeps/Action")
    store.record("actions", {"robot": "pepper"}, stored_type="printeps/Other")
    assert store.flush()
    client = make_client(store)
    body = client.get("/api/state/actions", params={"type": "printeps/Action", "seats": "2"}).json()
    assert body["count"] == 1 and body["documents"][0]["robot"] == "pepper"
    assert body["documents"][0]["_meta"]["stored_type"] == "printeps/Action"
    assert client.get("/api/state/actions", params={"since": "2999-01-01T00:00:00Z"}).json()["count"] == 0
    assert client.get("/api/state/actions", params={"order": "oldest", "limit": 1}).json()["documents"][0]["seats"] == 2


def test_bad_parameters_are_clear_422s(store) -> None:
    client = make_client(store)
    r = client.get("/api/state/actions", params={"since": "yesterday"})
    assert r.status_code == 422 and "since='yesterday'" in r.text
    r = client.get("/api/state/bad-name")
    assert r.status_code == 422 and "collection 'bad-name'" in r.text
    assert client.get("/api/state/actions", params={"limit": 0}).status_code == 422


def test_unreachable_db_is_503(mongo, tmp_path) -> None:
    from gateway.store.store import InformationState
    s = InformationState("mongodb://127.0.0.1:1/?directConnection=true", "x", tmp_path / "s.jsonl", timeout_ms=200)
    try:
        r = make_client(s).get("/api/state/actions")
        assert r.status_code == 503 and "unreachable" in r.text
    finally:
        s.close(flush_timeout_s=0.5)
