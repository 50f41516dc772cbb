"""KIE Server 7.x compatible endpoints, driven with the JSON a KIE Server client sends, over real HTTP."""

from __future__ import annotations

import httpx
import pytest

from api_helpers import files

BASE = "/kie-server/services/rest/server"
PKG = "org.printeps.apitest"


@pytest.fixture(scope="module")
def kie(live_server, client):
    assert client.put("/api/rulesets/kie", json={"files": files("k1")}).status_code == 201
    with httpx.Client(base_url=live_server.url, timeout=30,
                      headers={"Accept": "application/json", "Content-Type": "application/json"}) as c:
        yield c


def test_server_info(kie):
    body = kie.get(BASE).json()
    assert body["type"] == "SUCCESS" and body["msg"] == "Kie Server info"
    info = body["result"]["kie-server-info"]
    assert {"id", "version", "name", "location", "capabilities", "messages"} <= set(info)
    assert "KieServer" in info["capabilities"] and "BRM" in info["capabilities"]
    assert info["location"].endswith(BASE)


def test_containers(kie):
    body = kie.get(f"{BASE}/containers").json()
    assert body["type"] == "SUCCESS"
    containers = {c["container-id"]: c for c in body["result"]["kie-containers"]["kie-container"]}
    c = containers["kie"]
    assert c["status"] == "STARTED"
    assert c["release-id"] == {"group-id": "org.printeps.rules", "artifact-id": "kie", "version": "1"}
    assert c["resolved-release-id"] == c["release-id"]
    one = kie.get(f"{BASE}/containers/kie").json()
    assert one["type"] == "SUCCESS" and one["result"]["kie-container"]["container-id"] == "kie"
    missing = kie.get(f"{BASE}/containers/nope").json()
    assert missing == {"type": "FAILURE", "msg": "Container nope is not instantiated.", "result": None}


def test_batch_insert_fire_get_objects(kie):
    batch = {
        "lookup": "defaultKieSession",
        "commands": [
            {"insert": {"object": {f"{PKG}.Customer": {"id": "c1", "age": 30}},
                        "out-identifier": "customer", "return-object": True, "entry-point": "DEFAULT"}},
            {"insert": {"object": {f"{PKG}.Customer": {"id": "c2", "age": 5}}}},
            {"fire-all-rules": {"max": -1, "out-identifier": "fired"}},
            {"get-objects": {"class-object-filter": {"string": f"{PKG}.Customer"}, "out-identifier": "objects"}},
        ],
    }
    r = kie.post(f"{BASE}/containers/instances/kie", json=batch)
    assert r.status_code == 200
    assert r.headers["x-ruleset-version"] == "1"
    body = r.json()
    assert body["type"] == "SUCCESS" and body["msg"] == "Container kie successfully called."
    results = {x["key"]: x["value"] for x in body["result"]["execution-results"]["results"]}
    assert results["fired"] == 2
    assert results["customer"] == {f"{PKG}.Customer": {"id": "c1", "age": 30, "category": "adult"}}
    assert sorted(o[f"{PKG}.Customer"]["id"] for o in results["objects"]) == ["c1", "c2"]
    assert results["actions"] == [{"module": "say", "params": {"robot": "pepper", "text": "Welcome c1 (k1)"},
                                   "rule": "Greet adult"}]
    facts = body["result"]["execution-results"]["facts"]
    assert [f["key"] for f in facts] == ["customer"]
    handle = facts[0]["value"]["org.drools.core.common.DefaultFactHandle"]["external-form"]
    assert handle.endswith(f":DEFAULT:NON_TRAIT:{PKG}.Customer")


def test_two_fires_in_one_batch_keep_session_state(kie):
    batch = {"commands": [
        {"insert": {"object": {f"{PKG}.Customer": {"id": "a", "age": 50}}}},
        {"fire-all-rules": {"out-identifier": "first"}},
        {"insert-elements": {"objects": [{f"{PKG}.Customer": {"id": "b", "age": 60}}]}},
        {"fire-all-rules": {"out-identifier": "second"}},
        {"get-objects": {"out-identifier": "all"}},
    ]}
    body = kie.post(f"{BASE}/containers/instances/kie", json=batch).json()
    results = {x["key"]: x["value"] for x in body["result"]["execution-results"]["results"]}
    assert results["first"] == 2 and results["second"] == 2
    assert len(results["all"]) == 2
    assert [a["params"]["text"] for a in results["actions"]] == ["Welcome a (k1)", "Welcome b (k1)"]


def test_failures_are_kie_shaped(kie):
    r = kie.post(f"{BASE}/containers/instances/nope", json={"commands": [{"fire-all-rules": {}}]})
    assert r.status_code == 200
    assert r.json() == {"type": "FAILURE", "msg": "Container nope is not instantiated.", "result": None}
    for batch, expected in (
        ({"commands": [{"start-process": {"process-id": "p"}}]}, "not supported"),
        ({"commands": [{"insert": {"object": {f"{PKG}.Dragon": {"id": "d"}}}}, {"fire-all-rules": {}}]}, "Dragon"),
        ({"commands": [{"insert": {"object": {f"{PKG}.Customer": {"age": "old"}}}}, {"fire-all-rules": {}}]}, "age"),
        ({"commands": [{"set-global": {"identifier": "list", "object": []}}]}, "declares no global 'list'"),
        ({"commands": [{"query": {"name": "nope", "out-identifier": "q"}}]}, "query 'nope' failed"),
        ({"commands": []}, "no commands"),
    ):
        body = kie.post(f"{BASE}/containers/instances/kie", json=batch).json()
        assert body["type"] == "FAILURE", batch
        assert expected in body["msg"], body["msg"]
    r = kie.post(f"{BASE}/containers/instances/kie", content=b"{not json")
    assert r.status_code == 400 and "not valid JSON" in r.json()["error"]


def test_batch_query_and_globals(kie, client):
    qfiles = files("kq")
    qfiles["queries.drl"] = f"""package {PKG};
global java.util.List names;

query "customers older than" (int limit)
    $c: Customer(age > limit)
end

rule "collect names"
when
    $c: Customer()
then
    names.add($c.getId());
end
"""
    assert client.put("/api/rulesets/kieq", json={"files": qfiles}).status_code == 201
    batch = {"lookup": "defaultKieSession", "commands": [
        {"set-global": {"identifier": "names", "object": {"java.util.ArrayList": []}}},
        {"insert": {"object": {f"{PKG}.Customer": {"id": "c1", "age": 30}}}},
        {"insert": {"object": {f"{PKG}.Customer": {"id": "c2", "age": 5}}}},
        {"fire-all-rules": {}},
        {"query": {"name": "customers older than", "arguments": [18], "out-identifier": "older"}},
        {"get-global": {"identifier": "names", "out-identifier": "names"}},
    ]}
    body = kie.post(f"{BASE}/containers/instances/kieq", json=batch).json()
    assert body["type"] == "SUCCESS", body
    results = {r["key"]: r["value"] for r in body["result"]["execution-results"]["results"]}
    flat = results["older"]["org.drools.core.runtime.rule.impl.FlatQueryResults"]
    rows = flat["idResultMaps"]["element"]
    found = [e["value"][f"{PKG}.Customer"]["id"] for row in rows for e in row["element"] if e["key"] == "$c"]
    assert found == ["c1"]
    assert "$c" in flat["identifiers"]["element"]
    assert sorted(results["names"]) == ["c1", "c2"]
