"""The hot routes' fast paths (gateway.api.fast_paths: the REST fire, KIE command batches) answer
exactly as the FastAPI routes do.

Both apps run over the same real gateway (JVM + Drools, real MongoDB-protocol server); every
request is sent to the app with the fast path (the default) and to one with ``api.fire_fast_path``
off, and the answers are compared: status, body (less the decision's own id), the headers a
client reads.
"""

from __future__ import annotations

from typing import Any, Iterator

import pytest
from fastapi.testclient import TestClient

from api_helpers import FACTS, TOKENS, files
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
    yield from _apps(api_gateway, api_settings.api.model_validate({"tokens": TOKENS,
                                                                   "basic_users": "kieserver:kiepw:caller"}))


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


def _same_answer(apps: tuple[TestClient, TestClient], read: Any, path: str, **kwargs: Any) -> tuple:
    """The answer of the fast path, checked to be the FastAPI route's (``read`` reduces each)."""
    fast, routed = apps
    got = read(fast, path, **kwargs)
    assert got == read(routed, path, **kwargs)
    return got


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
    got = _same_answer(open_apps, _answer, f"/api/rulesets/{fire_set}/fire", **OPEN_CASES[case])
    if case == "fires":
        assert got[0] == 200 and got[1]["actions"][0]["params"]["text"] == "Welcome c1 (fp)"
    else:
        assert got[0] in (400, 413, 415, 422), got


@pytest.mark.parametrize("path", ["/api/rulesets/nope/fire", "/api/rulesets/-bad-/fire", "/api/rulesets/a%20b/fire"])
def test_unknown_and_malformed_rule_set_names_answer_as_the_route(open_apps, path):
    got = _same_answer(open_apps, _answer, path, json={"facts": FACTS})
    assert got[0] in (404, 422)


@pytest.mark.parametrize("headers", [{}, {"Authorization": "Bearer wrong"}, {"Authorization": "Basic a2llOnB3"},
                                     CALLER, AUTHOR])
def test_auth_on_the_fast_path_is_the_routes(secured_apps, fire_set, headers):
    got = _same_answer(secured_apps, _answer, f"/api/rulesets/{fire_set}/fire", json={"facts": FACTS}, headers=headers)
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


# ---- KIE command batches -----------------------------------------------------------------------------

KIE = "/kie-server/services/rest/server/containers/instances"
KIE_JSON = {"Content-Type": "application/json", "Accept": "application/json"}
PKG = "org.printeps.apitest"


def _kie_answer(client: TestClient, path: str, **kwargs: Any) -> tuple[int, Any, dict[str, str | None]]:
    """Status, body and headers of a KIE batch answer, less what differs from fire to fire and app
    to app (the decision's id, the app instance in the conversation id)."""
    r = client.post(path, **kwargs)
    try:
        body = r.json()
    except ValueError:
        body = r.text
    if isinstance(body, dict) and isinstance(body.get("result"), dict):
        results = body["result"].get("execution-results", {}).get("results", [])
        for item in results:
            if item.get("key") == "decision-id":
                item["value"] = "<id>"
        for item in body["result"].get("execution-results", {}).get("facts", []):
            item["value"] = "<handle>"  # a handle's external form holds the fact's identity hash
    headers = {h: r.headers.get(h) for h in ("content-type", "www-authenticate", "x-ruleset-version",
                                             "x-kie-conversationid")}
    headers["x-decision-id"] = "<id>" if r.headers.get("x-decision-id") else None
    if headers["x-kie-conversationid"]:  # its last part is the answering app's own instance id
        headers["x-kie-conversationid"] = headers["x-kie-conversationid"].rsplit("%3A", 1)[0]
    return r.status_code, body, headers


def _insert(cid: str, age: Any, **extra: Any) -> dict:
    return {"insert": {"object": {f"{PKG}.Customer": {"id": cid, "age": age}}, **extra}}


KIE_CASES = {
    "stateless fires at the end": dict(json={"commands": [_insert("k1", 30, **{"out-identifier": "c"}),
                                                          _insert("k2", 5)]}),
    "fires and counts": dict(json={"commands": [_insert("k1", 30), {"fire-all-rules": {"out-identifier": "n"}},
                                                {"get-objects": {"out-identifier": "all"}}]}),
    "bad field value": dict(json={"commands": [_insert("k1", "old")]}),
    "unknown command": dict(json={"commands": [{"start-process": {"processId": "p"}}]}),
    "unknown fact type": dict(json={"commands": [{"insert": {"object": {f"{PKG}.Dragon": {"id": "d"}}}}]}),
    "commands not a list": dict(json={"commands": {"insert": {}}}),
    "no commands": dict(json={}),
    "not JSON": dict(content=b'{"commands": [', headers=KIE_JSON),
    "empty body": dict(content=b"", headers=KIE_JSON),
    "too deep": dict(json={"commands": [[[[[[[[[[1]]]]]]]]]]}),
    "XML": dict(content=b"<batch-execution/>", headers={"Content-Type": "application/xml"}),
    "XStream": dict(json={"commands": []}, headers={"X-KIE-ContentType": "XSTREAM"}),
    "too large": dict(json={"commands": [_insert("x" * 5000, 1)]}),
    "unknown session": dict(json={"lookup": "nobody-has-this", "commands": [_insert("k1", 30)]}),
}


@pytest.mark.parametrize("case", sorted(KIE_CASES))
def test_the_kie_fast_path_answers_as_the_route(open_apps, fire_set, case):
    got = _same_answer(open_apps, _kie_answer, f"{KIE}/{fire_set}", **KIE_CASES[case])
    if case.startswith("stateless"):
        assert got[0] == 200 and got[1]["type"] == "SUCCESS" and got[2]["x-decision-id"] == "<id>"
    elif case != "fires and counts":
        assert got[0] in (400, 404, 413, 415, 422), got


@pytest.mark.parametrize("container", ["nope", "a%20b", "-bad-"])
def test_unknown_containers_answer_as_the_route(open_apps, container):
    got = _same_answer(open_apps, _kie_answer, f"{KIE}/{container}", json={"commands": [_insert("k1", 30)]})
    assert got[0] == 404 and got[1]["type"] == "FAILURE"


@pytest.mark.parametrize("headers", [{}, {"Authorization": "Bearer wrong"}, {"Authorization": "Basic a2llOnB3"},
                                     {"Authorization": "Basic !!not base64"}, {"Authorization": "Basic a2llc2VydmVy"},
                                     {"Authorization": "Basic a2llc2VydmVyOmtpZXB3"}, CALLER, AUTHOR])
def test_kie_auth_on_the_fast_path_is_the_routes(secured_apps, fire_set, headers):
    got = _same_answer(secured_apps, _kie_answer, f"{KIE}/{fire_set}", json={"commands": [_insert("k1", 30)]},
                       headers=headers)
    allowed = headers in (CALLER, AUTHOR) or headers.get("Authorization", "").endswith("a2llc2VydmVyOmtpZXB3")
    assert got[0] == (200 if allowed else 401), got
    assert got[1]["type"] == ("SUCCESS" if allowed else "FAILURE")


def test_a_stateful_kie_session_on_the_fast_path_keeps_its_facts(open_apps, fire_set, api_gateway, client):
    fast, _ = open_apps
    path = f"{KIE}/{fire_set}"
    first = fast.post(path, json={"lookup": "defaultKieSession", "commands": [_insert("s1", 30), {"fire-all-rules": {}}]},
                      headers={"X-Request-ID": "kie-fast-1"})  # a stateful batch is recorded when it fires
    assert first.status_code == 200, first.text
    second = fast.post(path, json={"lookup": "defaultKieSession",
                                   "commands": [{"get-objects": {"out-identifier": "all"}}, {"dispose": ""}]})
    values = {x["key"]: x["value"] for x in second.json()["result"]["execution-results"]["results"]}
    assert [o[f"{PKG}.Customer"]["id"] for o in values["all"]] == ["s1"]
    api_gateway.store.flush()
    decision = client.get(f"/api/decisions/{first.headers['X-Decision-Id']}").json()
    assert decision["origin"] == "kie" and decision["correlation_id"] == "kie-fast-1"
