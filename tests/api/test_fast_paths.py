"""The hot routes (the REST fire and KIE command batches, each one :class:`gateway.api.lean_route.LeanRoute`)
answer every kind of request as the API promises, and FastAPI still documents them.

The app runs over a real gateway (JVM + Drools, real MongoDB-protocol server); each case checks
the status, the body's kind of error and the headers a client reads.
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


def _app(api_gateway, api: Any) -> Iterator[TestClient]:
    with TestClient(create_app(api_gateway, api)) as app:
        yield app


@pytest.fixture(scope="module")
def open_app(api_settings, api_gateway) -> Iterator[TestClient]:
    yield from _app(api_gateway, api_settings.api.model_copy(update={"max_body_bytes": 4096, "max_json_depth": 8}))


@pytest.fixture(scope="module")
def secured_app(api_settings, api_gateway) -> Iterator[TestClient]:
    yield from _app(api_gateway, api_settings.api.model_validate({"tokens": TOKENS,
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


NESTED = {"facts": [{"type": "Customer", "id": "c1", "x": [[[[[[[[[1]]]]]]]]]}]}

# case -> (request, the status it answers, the field the error names or None)
OPEN_CASES = {
    "fires": (dict(json={"facts": FACTS}), 200),
    "bad field value": (dict(json={"facts": [{"type": "Customer", "id": "c1", "age": "old"}]}), 422),
    "unknown fact type": (dict(json={"facts": [{"type": "Dragon", "id": "d"}]}), 422),
    "fact without type": (dict(json={"facts": [{"id": "no type"}]}), 422),
    "facts not a list": (dict(json={"facts": {"type": "Customer"}}), 422),
    "no facts": (dict(json={"other": 1}), 422),
    "extra fields": (dict(json={"facts": [], "mode": "x"}), 422),
    "not JSON": (dict(content=b'{"facts": [', headers={"content-type": "application/json"}), 400),
    "empty body": (dict(content=b"", headers={"content-type": "application/json"}), 400),
    "too deep": (dict(json=NESTED), 400),
    "not JSON content type": (dict(content=b"facts=1", headers={"content-type": "application/x-www-form-urlencoded"}), 415),
    "too large": (dict(json={"facts": [{"type": "Customer", "id": "x" * 5000}]}), 413),
}


@pytest.mark.parametrize("case", sorted(OPEN_CASES))
def test_the_fire_route_answers_every_kind_of_request(open_app, fire_set, case):
    request, status = OPEN_CASES[case]
    got = _answer(open_app, f"/api/rulesets/{fire_set}/fire", **request)
    assert got[0] == status, got
    assert got[2]["content-type"] == "application/json"
    if case == "fires":
        assert got[1]["actions"][0]["params"]["text"] == "Welcome c1 (fp)"
    else:
        assert isinstance(got[1]["error"], str) and got[1]["error"], got


@pytest.mark.parametrize("path,status", [("/api/rulesets/nope/fire", 404), ("/api/rulesets/-bad-/fire", 422),
                                         ("/api/rulesets/a%20b/fire", 422)])
def test_unknown_and_malformed_rule_set_names(open_app, path, status):
    got = _answer(open_app, path, json={"facts": FACTS})
    assert got[0] == status, got
    if status == 422:  # named as FastAPI names a path parameter that does not match its pattern
        assert got[1]["errors"][0]["field"] == "path.name"


@pytest.mark.parametrize("headers", [{}, {"Authorization": "Bearer wrong"}, {"Authorization": "Basic a2llOnB3"},
                                     CALLER, AUTHOR])
def test_auth_on_the_fire_route(secured_app, fire_set, headers):
    got = _answer(secured_app, f"/api/rulesets/{fire_set}/fire", json={"facts": FACTS}, headers=headers)
    assert got[0] == (200 if headers in (CALLER, AUTHOR) else 401)
    if got[0] == 401:
        assert got[2]["www-authenticate"] == "Bearer"


def test_the_fire_route_records_the_decision_with_the_callers_id(open_app, fire_set, api_gateway, client):
    answer = open_app.post(f"/api/rulesets/{fire_set}/fire", json={"facts": FACTS},
                           headers={"traceparent": "00-4bf92f3577b34da6a3ce929d0e0e4736-00f067aa0ba902b7-01"}).json()
    api_gateway.store.flush()
    decision = client.get(f"/api/decisions/{answer['decision_id']}").json()
    assert decision["correlation_id"] == "4bf92f3577b34da6a3ce929d0e0e4736"
    assert decision["origin"] == "rest" and decision["ruleset"] == fire_set
    metrics = open_app.get("/metrics").text
    assert f'printeps_fires_total{{outcome="ok",ruleset="{fire_set}"}}' in metrics


def test_other_methods_and_paths_go_on_to_the_other_routes(open_app, fire_set):
    assert open_app.get(f"/api/rulesets/{fire_set}/fire").status_code == 405
    assert open_app.get(f"/api/rulesets/{fire_set}").json()["name"] == fire_set
    assert open_app.post(f"/api/rulesets/{fire_set}/fire/", json={"facts": FACTS},
                         follow_redirects=False).status_code in (307, 404)


def test_the_fire_route_serves_under_a_proxys_root_path(api_settings, api_gateway, fire_set):
    with TestClient(create_app(api_gateway, api_settings.api), root_path="/rules") as behind_proxy:
        r = behind_proxy.post(f"/api/rulesets/{fire_set}/fire", json={"facts": FACTS})
        assert r.status_code == 200 and r.json()["actions"][0]["params"]["text"] == "Welcome c1 (fp)"


def test_each_hot_route_is_defined_once_and_documented(open_app):
    """One route per endpoint (no second path to keep in step), and FastAPI's OpenAPI still has it
    with its parameters, body and security."""
    app = open_app.app
    fire = [r for r in app.routes if getattr(r, "path", None) == "/api/rulesets/{name}/fire"]
    batch = [r for r in app.routes if getattr(r, "path", None) == f"{KIE}/{{container_id}}"]
    assert len(fire) == 1 and len(batch) == 1
    assert not any("FastPaths" in type(m.cls).__name__ for m in app.user_middleware)
    spec = open_app.get("/openapi.json").json()
    fire_op = spec["paths"]["/api/rulesets/{name}/fire"]["post"]
    assert [p["name"] for p in fire_op["parameters"]] == ["name"]
    assert fire_op["parameters"][0]["schema"]["pattern"].startswith("^[A-Za-z0-9]")
    assert "facts" in fire_op["requestBody"]["content"]["application/json"]["schema"]["properties"]
    assert fire_op.get("security"), fire_op
    batch_op = spec["paths"][f"{KIE}/{{container_id}}"]["post"]
    assert "commands" in batch_op["requestBody"]["content"]["application/json"]["schema"]["properties"]
    assert len(batch_op["security"]) == 2  # bearer or basic, as KIE clients send


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
def test_the_kie_batch_route_answers_every_kind_of_request(open_app, fire_set, case):
    got = _kie_answer(open_app, f"{KIE}/{fire_set}", **KIE_CASES[case])
    if case.startswith("stateless"):
        assert got[0] == 200 and got[1]["type"] == "SUCCESS" and got[2]["x-decision-id"] == "<id>"
    elif case == "fires and counts":
        assert got[0] == 200 and got[1]["type"] == "SUCCESS", got
    elif case == "too large":  # refused by the body limit before any route
        assert got[0] == 413, got
    else:
        assert got[0] in (400, 404, 415, 422) and got[1]["type"] == "FAILURE", got


@pytest.mark.parametrize("container", ["nope", "a%20b", "-bad-"])
def test_unknown_containers(open_app, container):
    got = _kie_answer(open_app, f"{KIE}/{container}", json={"commands": [_insert("k1", 30)]})
    assert got[0] == 404 and got[1]["type"] == "FAILURE"


@pytest.mark.parametrize("headers", [{}, {"Authorization": "Bearer wrong"}, {"Authorization": "Basic a2llOnB3"},
                                     {"Authorization": "Basic !!not base64"}, {"Authorization": "Basic a2llc2VydmVy"},
                                     {"Authorization": "Basic a2llc2VydmVyOmtpZXB3"}, CALLER, AUTHOR])
def test_kie_auth_on_the_batch_route(secured_app, fire_set, headers):
    got = _kie_answer(secured_app, f"{KIE}/{fire_set}", json={"commands": [_insert("k1", 30)]}, headers=headers)
    allowed = headers in (CALLER, AUTHOR) or headers.get("Authorization", "").endswith("a2llc2VydmVyOmtpZXB3")
    assert got[0] == (200 if allowed else 401), got
    if not allowed:
        assert got[2]["www-authenticate"].startswith("Basic")
    assert got[1]["type"] == ("SUCCESS" if allowed else "FAILURE")


def test_a_stateful_kie_session_keeps_its_facts(open_app, fire_set, api_gateway, client):
    fast = open_app
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
