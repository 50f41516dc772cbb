"""The REST API over a real engine (JVM + Drools): manage versions, fire, errors, auth."""

from __future__ import annotations

import json

import pytest

from api_helpers import BROKEN, FACTS, TYPES, files
from gateway.base import jvm

DSL = '[when]There is a customer=$c : Customer()\n[then]Say hello=actions.say("pepper", "hello " + $c.getId());\n'
DSLR = (
    "package org.printeps.apitest;\n\nimport org.printeps.gateway.Actions;\n\nglobal Actions actions;\n\n"
    'expander greet.dsl\n\nrule "Hello"\nwhen\n    There is a customer\nthen\n    Say hello\nend\n'
)


@pytest.fixture(scope="module")
def deployed(client):
    """Rule set 'rest' with two versions (v1, v2) deployed."""
    assert client.put("/api/rulesets/rest", json={"files": files("v1"), "comment": "first"}).status_code == 201
    r = client.put("/api/rulesets/rest", json={"files": files("v2"), "comment": "second", "base_version": 1})
    assert r.status_code == 201, r.text
    assert r.json() == {"name": "rest", "version": 2}
    return "rest"


def test_list_get_and_versions(client, deployed):
    listed = {r["name"]: r for r in client.get("/api/rulesets").json()}
    assert listed["rest"]["version"] == 2
    assert {"name", "version", "deployed_at", "author", "comment"} <= set(listed["rest"])
    assert listed["rest"]["author"] == "anonymous" and listed["rest"]["comment"] == "second"
    current = client.get("/api/rulesets/rest").json()
    assert current["version"] == 2 and "(v2)" in current["files"]["greet.drl"]
    versions = client.get("/api/rulesets/rest/versions").json()
    assert [v["version"] for v in versions][:2] == [1, 2]
    assert "(v1)" in client.get("/api/rulesets/rest/versions/1").json()["files"]["greet.drl"]
    assert client.get("/api/rulesets/rest/versions/99").status_code == 404
    assert client.get("/api/rulesets/nope").status_code == 404


def test_fire_returns_actions_fired_and_facts(client, deployed):
    r = client.post("/api/rulesets/rest/fire", json={"facts": FACTS})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["version"] == 2
    assert body["actions"][0]["module"] == "say"
    assert body["actions"][0]["params"] == {"robot": "pepper", "text": "Welcome c1 (v2)"}
    assert [f["rule"] for f in body["fired"]] == ["Adult", "Greet adult"]
    assert {f["id"]: f["category"] for f in body["facts"]} == {"c1": "adult", "c2": None}


def test_fire_bad_facts_is_422_naming_fact_and_field(client, deployed):
    r = client.post("/api/rulesets/rest/fire", json={"facts": [{"type": "Customer", "id": "c1", "age": "old"}]})
    assert r.status_code == 422
    err = r.json()["errors"][0]
    assert err["index"] == 0 and err["field"] == "age"
    r = client.post("/api/rulesets/rest/fire", json={"facts": [{"type": "Dragon", "id": "d"}]})
    assert r.status_code == 422 and r.json()["errors"][0]["type"] == "Dragon"
    r = client.post("/api/rulesets/rest/fire", json={"facts": [{"id": "no type"}]})
    assert r.status_code == 422 and r.json()["kind"] == "facts"
    assert r.json()["errors"][0] == {"index": 0, "type": None, "id": "no type", "field": "type",
                                     "message": "a fact needs a non-empty string 'type'"}
    assert client.post("/api/rulesets/nope/fire", json={"facts": []}).status_code == 404


def test_deploy_that_does_not_compile_changes_nothing(client, deployed):
    r = client.put("/api/rulesets/rest", json={"files": BROKEN})
    assert r.status_code == 422
    err = r.json()["errors"][0]
    assert err["file"] == "greet.drl" and err["line"] > 0 and err["message"]
    assert client.get("/api/rulesets/rest").json()["version"] == 2


def test_stale_base_version_is_a_409(client, deployed):
    r = client.put("/api/rulesets/rest", json={"files": files("v9"), "base_version": 1})
    assert r.status_code == 409
    assert r.json()["error"] == "base version changed" and r.json()["current"] == 2


def test_validate_and_expand_deploy_nothing(client, deployed):
    ok = client.post("/api/rulesets/rest/validate", json={"files": files("v3")}).json()
    assert ok == {"ok": True, "errors": []}
    bad = client.post("/api/rulesets/rest/validate", json={"files": BROKEN}).json()
    assert bad["ok"] is False and bad["errors"][0]["file"] == "greet.drl"
    r = client.post("/api/rulesets/dsl/expand", json={"files": {"types.drl": TYPES, "greet.dsl": DSL, "greet.dslr": DSLR}})
    assert r.status_code == 200, r.text
    assert "Customer()" in r.json()["expanded"]["greet.dslr"]
    assert client.get("/api/rulesets/rest").json()["version"] == 2
    assert client.get("/api/rulesets/dsl").status_code == 404


def test_types_examples_diff(client):
    examples = [{"name": "one adult", "facts": [{"type": "Customer", "id": "c1", "age": 40}]}]
    r = client.put("/api/rulesets/extras", json={"files": {**files("e1"), "examples.json": json.dumps(examples)}})
    assert r.status_code == 201, r.text
    assert client.put("/api/rulesets/extras", json={"files": files("e2")}).status_code == 201
    types = client.get("/api/rulesets/extras/types").json()
    assert types["Customer"]["age"] == "int"
    assert client.get("/api/rulesets/extras/examples").json() == []  # v2 has no examples.json
    assert client.post("/api/rulesets/extras/rollback", json={"version": 1}).json()["version"] == 1
    assert client.get("/api/rulesets/extras/examples").json() == examples
    d = client.get("/api/rulesets/extras/diff", params={"from": 1, "to": 2}).json()
    assert set(d["files"]) == {"greet.drl", "examples.json"}
    assert "-    actions.say(\"pepper\", \"Welcome \" + $c.getId() + \" (e1)\");" in d["files"]["greet.drl"]


def test_try_fires_undeployed_text(client):
    r = client.post("/api/rulesets/draft/try", json={"files": files("draft"), "facts": FACTS})
    assert r.status_code == 200, r.text
    assert r.json()["actions"][0]["params"]["text"] == "Welcome c1 (draft)"
    r = client.post("/api/rulesets/draft/try", json={"files": BROKEN, "facts": FACTS})
    assert r.status_code == 422 and r.json()["errors"][0]["file"] == "greet.drl"
    assert client.get("/api/rulesets/draft").status_code == 404


def test_rollback_and_delete(client):
    client.put("/api/rulesets/rolled", json={"files": files("g1")})
    client.put("/api/rulesets/rolled", json={"files": files("g2")})
    assert client.post("/api/rulesets/rolled/rollback", json={"version": 1}).status_code == 200
    fired = client.post("/api/rulesets/rolled/fire", json={"facts": FACTS}).json()
    assert fired["version"] == 1 and fired["actions"][0]["params"]["text"].endswith("(g1)")
    assert client.post("/api/rulesets/rolled/rollback", json={"version": 7}).status_code == 404
    assert client.delete("/api/rulesets/rolled").json() == {"name": "rolled", "deleted": True}
    assert client.post("/api/rulesets/rolled/fire", json={"facts": FACTS}).status_code == 404
    assert client.delete("/api/rulesets/rolled").status_code == 404


def test_decisions_record_fires(client, deployed, api_gateway):
    fired = client.post("/api/rulesets/rest/fire", json={"facts": FACTS}, headers={"X-Request-ID": "req-42"}).json()
    assert fired["decision_id"]
    api_gateway.store.flush()
    recent = client.get("/api/decisions", params={"limit": 1, "ruleset": "rest", "origin": "rest"}).json()["decisions"]
    assert len(recent) == 1
    d = recent[0]
    assert d["decision_id"] == fired["decision_id"] and d["correlation_id"] == "req-42"
    assert d["ruleset"] == "rest" and d["version"] == 2 and d["fired"] == ["Adult", "Greet adult"]
    assert d["actions"][0]["module"] == "say" and d["at"] and d["origin"] == "rest"
    one = client.get(f"/api/decisions/{fired['decision_id']}").json()
    assert one["facts"] == FACTS and one["outcomes"] == []
    assert client.get("/api/decisions/000000000000000000000000").status_code == 404
    assert client.get("/api/decisions", params={"cursor": "nope"}).status_code == 422


def test_health_and_metrics(client, deployed):
    h = client.get("/health").json()
    assert h["status"] == "ok" and h["engine"]["rulesets"]["rest"] == 2
    assert h["store"]["status"] == "ok" and h["sync"]["status"] == "ok"
    non_heap = h["engine"]["jvm_non_heap"]  # what the soak plots beside the heap (a deploy leak shows here)
    assert 0 < non_heap["used"] <= non_heap["committed"] and non_heap["classes"] > 1000
    assert h["engine"]["jvm_aot_cache"] == jvm.aot_cache()  # the AOT class cache the JVM started from, or None
    client.post("/api/rulesets/rest/fire", json={"facts": FACTS})
    text = client.get("/metrics").text
    assert 'printeps_fires_total{outcome="ok",ruleset="rest"}' in text
    assert "printeps_fire_seconds_bucket" in text and "printeps_deploys_total" in text
    assert "printeps_errors_total" in text


def test_auth_roles(secured, deployed):
    author = {"Authorization": "Bearer tok-author"}
    caller = {"Authorization": "Bearer tok-caller"}
    assert secured.get("/api/rulesets").status_code == 401
    assert secured.get("/api/rulesets", headers={"Authorization": "Bearer wrong"}).status_code == 401
    assert secured.get("/api/whoami", headers=caller).json() == {"name": "bob", "role": "caller", "auth": "token"}
    assert secured.post("/api/rulesets/rest/fire", json={"facts": FACTS}, headers=caller).status_code == 200
    r = secured.put("/api/rulesets/authz", json={"files": files("a")}, headers=caller)
    assert r.status_code == 403 and "author" in r.json()["error"]
    assert secured.delete("/api/rulesets/rest", headers=caller).status_code == 403
    r = secured.put("/api/rulesets/authz", json={"files": files("a")}, headers=author)
    assert r.status_code == 201
    assert secured.get("/api/rulesets/authz", headers=author).json()["author"] == "alice"
    # basic auth is for the KIE Server endpoints only
    kie = ("kieserver", "kiepw")
    assert secured.get("/kie-server/services/rest/server", auth=kie).status_code == 200
    assert secured.get("/kie-server/services/rest/server", auth=("kieserver", "x")).status_code == 401
    assert secured.get("/api/rulesets", auth=kie).status_code == 401


def test_openapi_docs(client):
    spec = client.get("/openapi.json").json()
    assert "/api/rulesets/{name}/fire" in spec["paths"]
    assert "/kie-server/services/rest/server/containers/instances/{container_id}" in spec["paths"]
    assert client.get("/docs").status_code == 200


def test_fires_run_on_the_rule_sets_own_threads(api_settings, api_gateway, deployed):
    from fastapi.testclient import TestClient

    from gateway.api.main import create_app

    with TestClient(create_app(api_gateway, api_settings.api.model_copy(update={"fire_workers": 1}))) as c:
        r = c.post("/api/rulesets/rest/fire", json={"facts": FACTS})
        assert r.status_code == 200 and r.json()["version"] == 2
        assert c.post("/api/rulesets/rest/fire", json={"facts": [{"type": "Dragon"}]}).status_code == 422
        stats = c.app.state.bulkheads.stats()["rest"]  # the rule set's bulkhead fired both, on its one thread
        assert stats["threads"] == 1 and stats["waiting"] == 0 and stats["running"] == 0
