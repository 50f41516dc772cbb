"""Oversized and malformed bodies get a clear 4xx JSON error over real HTTP, and the server stays up."""

from __future__ import annotations

import socket

import httpx
import pytest

from api_helpers import FACTS, files


@pytest.fixture(scope="module")
def http(live_server, client):
    assert client.put("/api/rulesets/limits", json={"files": files("l1")}).status_code == 201
    with httpx.Client(base_url=live_server.url, timeout=30) as c:
        yield c


def _still_up(http) -> None:
    r = http.post("/api/rulesets/limits/fire", json={"facts": FACTS})
    assert r.status_code == 200 and r.json()["version"] >= 1


def test_oversized_body_is_413(http, api_settings):
    big = b'{"facts": [' + b'{"type": "Customer", "id": "x", "age": 1},' * 300_000 + b'{"type": "Customer"}]}'
    assert len(big) > api_settings.api.max_body_bytes
    r = http.post("/api/rulesets/limits/fire", content=big, headers={"Content-Type": "application/json"})
    assert r.status_code == 413 and "too large" in r.json()["error"]

    def chunks():  # no Content-Length: the cap must hold while streaming
        for _ in range(12):
            yield b" " * (1024 * 1024)

    r = http.post("/api/rulesets/limits/fire", content=chunks(), headers={"Content-Type": "application/json"})
    assert r.status_code == 413
    _still_up(http)


@pytest.mark.parametrize("body, status, words", [
    (b"{\"facts\": [", 400, "not valid JSON"),
    (b"", 400, "empty"),
    (b"[" * 200 + b"]" * 200, 400, "deeper"),
    (b"\xff\xfe garbage", 400, "not valid JSON"),
    (b'{"facts": "Customer"}', 422, "'facts' must be a list"),
    (b'{"facts": [{"type": "Customer", "age": 1e999}]}', 400, "infinity"),
])
def test_malformed_fire_bodies(http, body, status, words):
    r = http.post("/api/rulesets/limits/fire", content=body, headers={"Content-Type": "application/json"})
    assert r.status_code == status, r.text
    assert words in r.json()["error"]
    _still_up(http)


def test_malformed_management_bodies(http):
    r = http.put("/api/rulesets/limits", content=b"{\"files\": ", headers={"Content-Type": "application/json"})
    assert r.status_code == 400 and r.json()["kind"] == "body" and (r.json()["line"], r.json()["column"]) == (1, 11)
    r = http.put("/api/rulesets/limits", json={"files": {"a.drl": 3}})
    assert r.status_code == 422 and r.json()["errors"][0]["field"].startswith("body.files")
    r = http.put("/api/rulesets/limits", json={"files": {"../evil.drl": "rule"}})
    assert r.status_code == 422 and r.json()["errors"][0]["file"] == "../evil.drl"
    r = http.put("/api/rulesets/bad name!", json={"files": files()})
    assert r.status_code in (404, 422)
    r = http.post("/api/rulesets/limits/fire", content=b"facts=1", headers={"Content-Type": "application/x-www-form-urlencoded"})
    assert r.status_code == 415
    assert http.get("/no/such/route").json() == {"error": "Not Found", "kind": "not_found"}
    _still_up(http)


def test_garbage_on_the_socket_does_not_kill_the_server(http, live_server):
    with socket.create_connection(("127.0.0.1", live_server.port), timeout=5) as s:
        s.sendall(b"\x00\x01GARBAGE / HTTP/9.9\r\n\r\n")
        try:
            s.recv(1024)
        except OSError:
            pass
    _still_up(http)


def test_the_depth_limit_holds_at_its_edge_with_or_without_the_walk():
    """parse_json skips the depth walk when the body has no more '[' and '{' than the limit; at the
    limit a body passes, one level more is refused, and brackets inside strings change neither."""
    from gateway.api.jsonio import BadBody, parse_json

    def nested(levels: int, text: str = "x") -> bytes:
        return ("[" * (levels - 1) + '{"a": "' + text + '"}' + "]" * (levels - 1)).encode()

    assert parse_json(nested(8), 8) is not None  # 8 openers: no walk
    assert parse_json(nested(8, "[[[[{{{{"), 8) is not None  # 16 openers, 8 levels: the walk says yes
    for body in (nested(9), nested(9, "[[[[")):
        with pytest.raises(BadBody, match="deeper than 8 levels"):
            parse_json(body, 8)
