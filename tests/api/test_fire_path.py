"""The fire route's fast path (gateway.api.fire_path) answers exactly as the FastAPI route does.

Both apps run over the same real gateway (JVM + Drools, real MongoDB-protocol server); every
request is sent to the app with the fast path (the default) and to one with ``api.fire_fast_path``
off, and the answers are compared: status, body (less the decision's own id), the headers a
client reads.
"""

from __future__ import annotations

from typing import Any, Iterator

import pytest
from fastapi.testclient import TestClient

from api_helpers import FACTS, files
from conftest import TOKENS
from gateway.api.main import create_app

AUTHOR = {"Authorization": "Bearer tok-author"}
CALLER = {"Authorization": "Bearer tok-caller"}


@pytest.fixture(scope="module")
def fire_set(client) -> str:
    assert client.put("/api/rulesets/fastpath", json={"files": files("fp")}).status_code == 201
    return "fastpath"


def _apps(api_gateway, api: Any) -> Iterator[tuple[TestClient, TestClient]]:
    with TestClient(create_app(api_gateway, api)) as fast, \
            TestClient(create_app(api_gateway, api.model_copy(update={"fire_fast_path": False}))) as routed:
        yield fast, routed


@pytest.fixture(scope="module")
def open_apps(api_settings, api_gateway) -> Iterator[tuple[TestClient, TestClient]]:
    yield from _apps(api_gateway, api_settings.api.model_copy(update={"max_body_bytes": 4096, "max_json_depth": 8}))


@pytest.fixture(scope="module")
def secured_apps(api_settings, api_gateway) -> Iterator[tuple[TestClient, TestClient]]:
    yield from _apps(api_gateway, api_settings.api.model_validate({"tokens": TOKENS}))


def _answer(client: TestClient, path: str, **kwargs: Any) -> tuple[int, Any, dict[str, str | None]]:
    r = client.post(path, **kwargs)
    try:
        body = r.json()
    except ValueError:
        body = r.text
    if isinstance(body, dict):
        body.pop("decision_id", None)
        body.pop("duration_ms", None)  # the decision's own id and time differ from fire to fire
    headers = {h: r.headers.get(h) for h in ("content-type", "www-authenticate")}
    return r.status_code, body, headers


NESTED = {"facts": [{"type": "Customer", "id": "c1", "x": [[[[[[[[[1]]]]]]]]]}]}

OPEN_CASES = {
    "fires": dict(json={"facts": FACTS}),
    "bad field value": dict(json={"facts": [{"type": "Customer", "id": "c1", "age": "old"}]}),
    "unknown fact type": dict(json={"facts": [{"type": "Dragon", "id": "d"}]}),
    "fact without type": dict(json={"facts": [{"id": "no type"}]}),
    "facts not a list": dict(json={"facts": {"type": "Customer"}}),
    "no facts": dict(json={"other": 1}),
    "extra fields": dict(json={"facts": [], "mode": "x"}),
    "not JSON": dict(content=b'{"facts": [', headers={"content-type": "application/json"}),
    "empty body": dict(content=b"", headers={"content-type": "application/json"}),
    "too deep": dict(json=NESTED),
    "not JSON content type": dict(content=b"facts=1", headers={"content-type": "application/x-www-form-urlencoded"}),
    "too large": dict(json={"facts": [{"type": "Customer", "id": "x" * 5000}]}),
}


@pytest.mark.parametrize("case", sorted(OPEN_CASES))
def test_the_fast_path_answers_as_the_route(open_apps, fire_set, case):
    fast, routed = open_apps
    kwargs = OPEN_CASES[case]
    got, expected = _answer(fast, f"/api/rulesets/{fire_set}/fire", **kwargs), _answer(routed, f"/api/rulesets/{fire_set}/fire", **kwargs)
    assert got == expected
    if case == "fires":
        assert got[0] == 200 and got[1]["actions"][0]["params"]["text"] == "Welcome c1 (fp)"
    else:
        assert got[0] in (400, 413, 415, 422), got


@pytest.mark.parametrize("path", ["/api/rulesets/nope/fire", "/api/rulesets/-bad-/fire", "/api/rulesets/a%20b/fire"])
def test_unknown_and_malformed_rule_set_names_answer_as_the_route(open_apps, path):
    fast, routed = open_apps
    got = _answer(fast, path, json={"facts": FACTS})
    assert got == _answer(routed, path, json={"facts": FACTS})
    assert got[0] in (404, 422)


@pytest.mark.parametrize("headers", [{}, {"Authorization": "Bearer wrong"}, {"Authorization": "Basic a2llOnB3"},
                                     CALLER, AUTHOR])
def test_auth_on_the_fast_path_is_the_routes(secured_apps, fire_set, headers):
    fast, routed = secured_apps
    got = _answer(fast, f"/api/rulesets/{fire_set}/fire", json={"facts": FACTS}, headers=headers)
    assert got == _answer(routed, f"/api/rulesets/{fire_set}/fire", json={"facts": FACTS}, headers=headers)
    assert got[0] == (200 if headers in (CALLER, AUTHOR) else 401)


def test_the_fast_path_records_the_decision_with_the_callers_id(open_apps, fire_set, api_gateway, client):
    fast, _ = open_apps
    answer = fast.post(f"/api/rulesets/{fire_set}/fire", json={"facts": FACTS},
                       headers={"traceparent": "00-4bf92f3577b34da6a3ce929d0e0e4736-00f067aa0ba902b7-01"}).json()
    api_gateway.store.flush()
    decision = client.get(f"/api/decisions/{answer['decision_id']}").json()
    assert decision["correlation_id"] == "4bf92f3577b34da6a3ce929d0e0e4736"
    assert decision["origin"] == "rest" and decision["ruleset"] == fire_set
    metrics = fast.get("/metrics").text
    assert f'printeps_fires_total{{outcome="ok",ruleset="{fire_set}"}}' in metrics


def test_other_methods_and_paths_go_on_to_fastapi(open_apps, fire_set):
    fast, routed = open_apps
    for method, path in (("GET", f"/api/rulesets/{fire_set}/fire"), ("POST", f"/api/rulesets/{fire_set}/fire/"),
                         ("GET", f"/api/rulesets/{fire_set}")):
        a, b = fast.request(method, path, follow_redirects=False), routed.request(method, path, follow_redirects=False)
        assert a.status_code == b.status_code, (method, path)


def test_the_fast_path_serves_under_a_proxys_root_path(api_settings, api_gateway, fire_set):
    with TestClient(create_app(api_gateway, api_settings.api), root_path="/rules") as behind_proxy:
        r = behind_proxy.post(f"/api/rulesets/{fire_set}/fire", json={"facts": FACTS})
        assert r.status_code == 200 and r.json()["actions"][0]["params"]["text"] == "Welcome c1 (fp)"
