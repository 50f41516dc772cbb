"""The KIE documentation's request bodies (tests/api/kie_docs/*.json), sent unchanged over real
HTTP, and a KIE client library from PyPI (python-drools-sdk) pointed at this gateway."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import httpx
import pytest

BASE = "/kie-server/services/rest/server"
DOCS = Path(__file__).parent / "kie_docs"
PKG = "org.drools.compiler.test"
HANDLE = "org.drools.core.common.DefaultFactHandle"

KIEDOCS = {
    "person.drl": f"""package {PKG};
import org.printeps.gateway.Actions;
global Actions actions;
global Person helper;

declare Person
    name : String
    age : int
end

query "persons"
    $p : Person()
end

rule "Adult"
when
    $p : Person( age >= 18 )
then
    actions.say("pepper", "Hello " + $p.getName());
end

rule "Streamed"
when
    $p : Person() from entry-point "my stream"
then
    actions.say("pepper", "streamed " + $p.getName());
end
""",
    "kmodule.xml": """<?xml version="1.0" encoding="UTF-8"?>
<kmodule xmlns="http://www.drools.org/xsd/kmodule">
  <kbase name="kbase1" default="true" packages="org.drools.compiler.test">
    <ksession name="ksession1" type="stateful" default="true" clockType="pseudo"/>
    <ksession name="stateless1" type="stateless" default="true"/>
  </kbase>
</kmodule>
""",
}


def doc(name: str) -> dict:
    return json.loads((DOCS / name).read_text())


@pytest.fixture(scope="module")
def kie(live_server, client):
    assert client.put("/api/rulesets/kiedocs", json={"files": KIEDOCS}).status_code == 201
    with httpx.Client(base_url=live_server.url, timeout=30, headers={"Content-Type": "application/json",
                                                                     "Accept": "application/json"}) as c:
        yield c
    client.delete("/api/rulesets/kiedocs/sessions/ksession1")


def post(kie, body: dict) -> httpx.Response:
    return kie.post(f"{BASE}/containers/instances/kiedocs", json=body)


def results(r: httpx.Response) -> dict:
    body = r.json()
    assert body["type"] == "SUCCESS", body
    return {x["key"]: x["value"] for x in body["result"]["execution-results"]["results"]}


def facts(r: httpx.Response) -> dict:
    return {x["key"]: x["value"] for x in r.json()["result"]["execution-results"]["facts"]}


def test_documented_bodies_run_unchanged(kie):
    r = post(kie, doc("batch-execution.json"))
    assert results(r)["firedActivations"] == 1
    assert results(r)["actions"][0]["params"]["text"] == "Hello john"
    r = post(kie, doc("rest-api-insert-and-fire.json"))  # {"fire-all-rules": ""}
    out = results(r)
    assert out["mary"] == {f"{PKG}.Person": {"name": "mary", "age": 31}}
    assert [a["params"]["text"] for a in out["actions"]] == ["Hello mary"]
    assert facts(r)["mary"][HANDLE]["external-form"].endswith(f":DEFAULT:NON_TRAIT:{PKG}.Person")
    # no lookup: the rule set's default stateless ksession, which fires at the end like KIE's
    r = post(kie, doc("insert-object.json"))
    out = results(r)
    assert "john" not in out  # return-object false
    assert facts(r)["john"][HANDLE]["external-form"].split(":")[5] == "my stream"
    assert [a["params"]["text"] for a in out["actions"]] == ["streamed john"]
    r = post(kie, doc("insert-elements.json"))
    assert sorted(a["params"]["text"] for a in results(r)["actions"]) == ["Hello john", "Hello sarah"]
    assert results(post(kie, doc("fire-all-rules.json")))["firedActivations"] == 0
    assert results(post(kie, doc("get-objects.json")))["objects"] == []  # a fresh stateless session


def test_documented_handle_is_stale_then_real_handles_work(kie):
    for name in ("retract.json", "modify.json", "get-object.json"):
        r = post(kie, doc(name))
        assert r.status_code == 422, r.text
        body = r.json()
        assert body["type"] == "FAILURE" and body["result"] is None
        assert "command 0" in body["msg"] and "0:234:345:456:567:789" in body["msg"], body["msg"]
    inserted = post(kie, {"lookup": "ksession1", "commands": [
        {"insert": {"object": {f"{PKG}.Person": {"name": "ann", "age": 17}}, "out-identifier": "ann"}}]})
    handle = facts(inserted)["ann"][HANDLE]["external-form"]
    for name in ("modify.json", "get-object.json", "retract.json"):
        body = copy.deepcopy(doc(name))
        body["lookup"] = "ksession1"
        command = next(iter(body["commands"][0].values()))
        command["fact-handle"] = handle
        out = results(post(kie, body))
        if name == "get-object.json":
            assert out["john"] == {f"{PKG}.Person": {"name": "ann", "age": 42}}  # modified by modify.json
    out = results(post(kie, {"lookup": "ksession1", "commands": [{"get-objects": {"out-identifier": "all"}}]}))
    assert "ann" not in [o[f"{PKG}.Person"]["name"] for o in out["all"]]


def test_documented_query_and_globals(kie):
    post(kie, {"lookup": "ksession1", "commands": [{"insert": {"object": {f"{PKG}.Person": {"name": "qq", "age": 50}}}}]})
    for name in ("query.json", "set-global.json", "get-global.json"):
        body = doc(name)
        body["lookup"] = "ksession1"
        out = results(post(kie, body))
        if name == "query.json":
            rows = out["persons"]["org.drools.core.runtime.rule.impl.FlatQueryResults"]["idResultMaps"]["element"]
            assert "qq" in [e["value"][f"{PKG}.Person"]["name"] for row in rows for e in row["element"] if e["key"] == "$p"]
        if name == "set-global.json":
            assert out["output"] == {f"{PKG}.Person": {"name": "kyle", "age": 30}}
        if name == "get-global.json":
            assert out["helperOutput"] == {f"{PKG}.Person": {"name": "kyle", "age": 30}}


def test_documented_process_command_is_refused(kie):
    r = post(kie, doc("start-process.json"))
    assert r.status_code == 422
    assert r.json()["type"] == "FAILURE" and "processes are not supported" in r.json()["msg"]


def test_documented_container_payloads(kie, client):
    r = kie.put(f"{BASE}/containers/kiedocs", json=doc("create-container.json"))
    assert r.status_code == 400 and r.json()["msg"] == "Container kiedocs already exists."
    r = kie.post(f"{BASE}/containers/kiedocs/release-id", json=doc("update-release-id.json"))
    assert r.json()["type"] == "SUCCESS" and r.json()["result"]["release-id"]["artifact-id"] == "kiedocs"


def test_python_kie_client_from_pypi(kie, live_server):
    """python-drools-sdk (PyPI) talks to KIE Server's REST API; pointed at this gateway it inserts
    objects named by their Python class, sends {"fire-all-rules": ""} and reads the results by
    fully qualified class name."""
    sdk = pytest.importorskip("python_drools_sdk.kie.drools", reason="pip install --no-deps python-drools-sdk jsons typish")
    from python_drools_sdk.commands.insert_elements_command import InsertElementsCommand
    from python_drools_sdk.commands.insert_object_command import InsertObjectCommand
    from python_drools_sdk.utils.data_store import DataStore

    class Person:  # the SDK sends the class's name and the instance's attributes
        def __init__(self, name: str, age: int) -> None:
            self.name = name
            self.age = age

    drools = sdk.Drools
    drools.KIE_SERVER_ROOT_URL = live_server.url
    drools.KIE_SERVER_USERNAME = drools.KIE_SERVER_PASSWORD = "unused"
    drools.KIE_SERVER_CONTAINER_ID = "kiedocs"
    drools.KIE_SERVER_CONTAINER_PACKAGE = PKG
    drools.KIE_SESSION_NAME = "ksession1"
    try:
        drools.reset_commands()
        DataStore.reset()
        drools.add_command(InsertObjectCommand(object=Person("sdk-adult", 40), out_identifier="adult").initialize())
        drools.add_command(InsertElementsCommand(objects=[Person("sdk-a", 1), Person("sdk-b", 2)],
                                                 out_identifier="kids").initialize())
        data = drools.execute_commands()
        assert data["adult"] == {"name": "sdk-adult", "age": 40}
        assert sorted(k["name"] for k in data["kids"]) == ["sdk-a", "sdk-b"]
        # the facts stayed in ksession1: a second call sees them
        drools.reset_commands()
        DataStore.reset()
        drools.add_command(InsertObjectCommand(object=Person("sdk-second", 20), out_identifier="second").initialize())
        assert drools.execute_commands()["second"]["name"] == "sdk-second"
    finally:
        drools.reset_commands()
        DataStore.reset()
    names = [o[f"{PKG}.Person"]["name"] for o in results(post(kie, {"lookup": "ksession1", "commands": [
        {"get-objects": {"out-identifier": "all"}}]}))["all"]]
    assert {"sdk-adult", "sdk-a", "sdk-b", "sdk-second"} <= set(names)
