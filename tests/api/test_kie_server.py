"""KIE Server 7.x compatible endpoints, driven with the JSON a KIE Server client sends, over real HTTP:
sessions that keep their facts (lookup), fact handles, max, the session clock with a temporal rule,
every rule command, failures in KIE's shape, the container lifecycle and live sessions on deploy."""

from __future__ import annotations

import httpx
import pytest
from api_helpers import files

BASE = "/kie-server/services/rest/server"
PKG = "org.printeps.apitest"
HANDLE = "org.drools.core.common.DefaultFactHandle"

TEMPORAL = {"visits.drl": """package org.printeps.temporal;
import org.printeps.gateway.Actions;
global Actions actions;

declare Visit
    @role(event)
    @timestamp(ts)
    id : String
    ts : long
end

rule "Crowd"
when
    Number( intValue >= 3 ) from accumulate( Visit() over window:time( 10s ), count(1) )
then
    actions.say("pepper", "crowd");
end

rule "No answer"
when
    $q : Visit( id == "question" )
    not Visit( id == "answer", this after[0s, 5s] $q )
then
    actions.say("pepper", "no answer to " + $q.getId());
end
"""}


@pytest.fixture(scope="module")
def kie(live_server, client):
    assert client.put("/api/rulesets/kie", json={"files": files("k1")}).status_code == 201
    with httpx.Client(base_url=live_server.url, timeout=30,
                      headers={"Accept": "application/json", "Content-Type": "application/json"}) as c:
        yield c


def batch(kie, commands, lookup="defaultKieSession", container="kie", **extra):
    body = {"commands": commands, **extra}
    if lookup is not None:
        body["lookup"] = lookup
    return kie.post(f"{BASE}/containers/instances/{container}", json=body)


def results(r: httpx.Response) -> dict:
    body = r.json()
    assert r.status_code == 200 and body["type"] == "SUCCESS", body
    return {x["key"]: x["value"] for x in body["result"]["execution-results"]["results"]}


def handles(r: httpx.Response) -> dict:
    return {x["key"]: x["value"] for x in r.json()["result"]["execution-results"]["facts"]}


def customer(cid: str, age: int) -> dict:
    return {f"{PKG}.Customer": {"id": cid, "age": age}}


def dispose(kie, container="kie", lookup="defaultKieSession") -> None:
    results(batch(kie, [{"dispose": ""}], lookup=lookup, container=container))


def test_server_info_readycheck_healthcheck(kie):
    body = kie.get(BASE).json()
    assert body["type"] == "SUCCESS" and body["msg"] == "Kie Server info"
    info = body["result"]["kie-server-info"]
    assert {"id", "version", "name", "location", "capabilities", "messages"} <= set(info)
    assert "KieServer" in info["capabilities"] and "BRM" in info["capabilities"]
    assert info["location"].endswith(BASE)
    assert kie.get(f"{BASE}/readycheck").status_code == 200
    assert kie.get(f"{BASE}/healthcheck").status_code == 200
    report = kie.get(f"{BASE}/healthcheck", params={"report": "true"}).json()
    assert {"severity", "timestamp", "content"} <= set(report[0])
    assert any("engine: ok" in m["content"][0] for m in report)


def test_containers(kie):
    body = kie.get(f"{BASE}/containers").json()
    assert body["type"] == "SUCCESS"
    containers = {c["container-id"]: c for c in body["result"]["kie-containers"]["kie-container"]}
    c = containers["kie"]
    assert c["status"] == "STARTED"
    assert c["release-id"] == {"group-id": "org.printeps.rules", "artifact-id": "kie", "version": "1"}
    assert c["resolved-release-id"] == c["release-id"]
    assert {s["name"] for s in c["ksessions"]} == {"defaultKieSession", "defaultStatelessKieSession"}
    filtered = kie.get(f"{BASE}/containers", params={"artifactId": "kie"}).json()["result"]["kie-containers"]["kie-container"]
    assert [x["container-id"] for x in filtered] == ["kie"]
    one = kie.get(f"{BASE}/containers/kie").json()
    assert one["type"] == "SUCCESS" and one["result"]["kie-container"]["container-id"] == "kie"
    missing = kie.get(f"{BASE}/containers/nope")
    assert missing.status_code == 200  # as KIE Server: clients branch on "type" here
    assert missing.json() == {"type": "FAILURE", "msg": "Container nope is not instantiated.", "result": None}


def test_stateful_session_keeps_facts_across_calls(kie):
    first = batch(kie, [
        {"insert": {"object": customer("c1", 30), "out-identifier": "customer", "return-object": True,
                    "entry-point": "DEFAULT", "disconnected": False}},
        {"insert": {"object": customer("c2", 5)}},
        {"fire-all-rules": {"max": -1, "out-identifier": "fired"}},
    ])
    out = results(first)
    assert first.headers["x-ruleset-version"] == "1" and first.headers["x-session-id"] == "defaultKieSession"
    assert out["fired"] == 2
    assert out["customer"] == {f"{PKG}.Customer": {"id": "c1", "age": 30, "category": "adult"}}
    assert out["actions"] == [{"module": "say", "params": {"robot": "pepper", "text": "Welcome c1 (k1)"}, "rule": "Greet adult"}]
    handle = handles(first)["customer"][HANDLE]["external-form"]
    assert handle.startswith("0:") and handle.endswith(f":DEFAULT:NON_TRAIT:{PKG}.Customer")
    # a second call reaches the same live session: the facts are there, rules fire on them
    second = batch(kie, [
        {"insert": {"object": customer("c3", 40)}},
        {"fire-all-rules": {"out-identifier": "fired"}},
        {"get-objects": {"class-object-filter": {"string": f"{PKG}.Customer"}, "out-identifier": "objects"}},
        {"get-fact-handles": {"out-identifier": "handles"}},
        {"get-object": {"fact-handle": handle, "out-identifier": "c1"}},
    ])
    out = results(second)
    assert out["fired"] == 2  # c3 only: c1's firings are not repeated
    assert sorted(o[f"{PKG}.Customer"]["id"] for o in out["objects"]) == ["c1", "c2", "c3"]
    assert handle in [h[HANDLE]["external-form"] for h in out["handles"]]
    assert out["c1"][f"{PKG}.Customer"]["id"] == "c1"
    dispose(kie)
    out = results(batch(kie, [{"get-objects": {"out-identifier": "objects"}}]))
    assert out["objects"] == []  # a lookup after dispose starts a new, empty session


def test_no_lookup_is_stateless_and_fires_at_the_end(kie):
    body = {"commands": [{"insert": {"object": customer("s1", 30), "out-identifier": "s1"}}]}
    out = results(kie.post(f"{BASE}/containers/instances/kie", json=body))
    assert out["s1"] == {f"{PKG}.Customer": {"id": "s1", "age": 30, "category": "adult"}}  # fired at the end
    out = results(batch(kie, [{"get-objects": {"out-identifier": "objects"}}], lookup=None))
    assert out["objects"] == []
    one = kie.post(f"{BASE}/containers/instances/kie", json={"fire-all-rules": ""})  # a bare command
    # every fire is a recorded decision; KIE reads "" as FireAllRulesCommand("") and keys the count by ""
    assert set(results(one)) == {"", "actions", "decision-id"}


def test_fact_handles_modify_update_retract(kie):
    r = batch(kie, [{"insert": {"object": customer("h1", 10), "out-identifier": "h1"}},
                    {"insert": {"object": customer("h2", 12), "out-identifier": "h2"}}])
    h1 = handles(r)["h1"]  # the handle object as KIE returned it is accepted as it is
    h2 = handles(r)["h2"][HANDLE]["external-form"]
    out = results(batch(kie, [
        {"modify": {"fact-handle": h1, "setters": [{"accessor": "age", "value": "20"}]}},
        {"fire-all-rules": {"out-identifier": "fired"}},
        {"update": {"fact-handle": h2, "object": customer("h2", 70)}},
        {"fire-all-rules": {"out-identifier": "fired2"}},
        {"get-object": {"fact-handle": h1, "out-identifier": "h1"}},
        {"get-object": {"fact-handle": h2, "out-identifier": "h2"}},
    ]))
    assert out["h1"] == {f"{PKG}.Customer": {"id": "h1", "age": 20, "category": "adult"}}
    assert out["h2"] == {f"{PKG}.Customer": {"id": "h2", "age": 70, "category": "adult"}}
    assert out["fired"] == 2 and out["fired2"] == 2
    results(batch(kie, [{"retract": {"fact-handle": h1}}, {"delete": {"fact-handle": h2}}]))
    stale = batch(kie, [{"insert": {"object": customer("h3", 1)}}, {"retract": {"fact-handle": h1}}])
    assert stale.status_code == 422
    msg = stale.json()["msg"]
    assert "command 1 (retract)" in msg and "is not in this session" in msg and "nothing was executed" in msg
    out = results(batch(kie, [{"get-objects": {"out-identifier": "objects"}}]))
    assert [o[f"{PKG}.Customer"]["id"] for o in out["objects"]] == []  # h3 was not inserted: all or nothing
    dispose(kie)


def test_fire_all_rules_max(kie):
    results(batch(kie, [{"insert": {"object": customer(f"m{k}", 30)}} for k in range(3)]))
    out = results(batch(kie, [{"fire-all-rules": {"max": 1, "out-identifier": "fired"}}]))
    assert out["fired"] == 1 and len(out["actions"]) == 0  # one "Adult" firing, no greeting yet
    out = results(batch(kie, [{"fire-all-rules": {"max": 2, "out-identifier": "fired"}}]))
    assert out["fired"] == 2
    out = results(batch(kie, [{"fire-all-rules": {"out-identifier": "fired"}}]))
    assert out["fired"] == 3  # the rest
    dispose(kie)


def test_bad_input_is_a_kie_failure_naming_the_command(kie):
    r = batch(kie, [{"fire-all-rules": {}}], container="nope")
    assert r.status_code == 404
    assert r.json() == {"type": "FAILURE", "msg": "Container nope is not instantiated.", "result": None}
    results(batch(kie, [{"insert": {"object": customer("keep", 1)}}]))
    for commands, status, expected in (
        ([{"start-process": {"process-id": "p"}}], 422, "command 0 (start-process): processes are not supported"),
        ([{"complete-work-item": {"id": 1}}], 422, "processes are not supported"),
        ([{"insert": {"object": customer("x", 1)}}, {"frobnicate": {}}], 422, "command 1 (frobnicate): unknown command"),
        ([{"insert": {"object": {f"{PKG}.Dragon": {"id": "d"}}}}], 422, "command 0 (insert): unknown fact class 'org.printeps.apitest.Dragon'"),
        ([{"insert": {"object": {"com.elsewhere.Customer": {"id": "d"}}}}], 422, "unknown fact class"),
        ([{"insert": {"object": customer("x", 1)}}, {"insert": {"object": {f"{PKG}.Customer": {"age": "old"}}}}], 422,
         "command 1 (insert)"),
        ([{"insert": {"object": {f"{PKG}.Customer": {"agee": 3}}}}], 422, "unknown field 'agee'"),
        ([{"set-global": {"identifier": "list", "object": []}}], 422, "declares no global 'list'"),
        ([{"query": {"name": "nope", "out-identifier": "q"}}], 422, "has no query 'nope'"),
        ([{"advance-session-time": {"amount": -5}}], 422, "must not be negative"),
        ([{"fire-all-rules": []}], 422, "its arguments must be an object"),
        ([], 400, "no commands"),
    ):
        r = batch(kie, commands)
        assert r.status_code == status, (commands, r.text)
        body = r.json()
        assert body["type"] == "FAILURE" and body["result"] is None
        assert expected in body["msg"], body["msg"]
    out = results(batch(kie, [{"get-objects": {"out-identifier": "objects"}}]))
    assert [o[f"{PKG}.Customer"]["id"] for o in out["objects"]] == ["keep"]  # the refused batches changed nothing
    r = batch(kie, [{"fire-all-rules": ""}], lookup="noSuchSession")
    assert r.status_code == 404 and r.json()["msg"].startswith("Session 'noSuchSession' not found on container 'kie'")
    r = kie.post(f"{BASE}/containers/instances/kie", content=b"{not json")
    assert r.status_code == 400 and r.json()["type"] == "FAILURE" and "not valid JSON" in r.json()["msg"]
    for headers in ({"X-KIE-ContentType": "XSTREAM"}, {"X-KIE-ContentType": "JAXB"}, {"Content-Type": "application/xml"}):
        r = kie.post(f"{BASE}/containers/instances/kie", content=b"<batch-execution/>", headers=headers)
        assert r.status_code == 415 and r.json()["type"] == "FAILURE" and "JSON" in r.json()["msg"]
    r = kie.get(f"{BASE}/containers/kie/processes/definitions")
    assert r.status_code == 404 and r.json()["type"] == "FAILURE"
    dispose(kie)


def test_queries_globals_agenda_groups(kie, client):
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

rule "late shift" agenda-group "night"
when
    $c: Customer(age > 60)
then
    names.add("night " + $c.getId());
end
"""
    assert client.put("/api/rulesets/kieq", json={"files": qfiles}).status_code == 201
    out = results(batch(kie, [
        {"set-global": {"identifier": "names", "object": {"java.util.ArrayList": []}}},
        {"insert": {"object": customer("c1", 30)}},
        {"insert": {"object": customer("c2", 65)}},
        {"fire-all-rules": {}},
        {"query": {"name": "customers older than", "arguments": [18], "out-identifier": "older"}},
        {"get-global": {"identifier": "names", "out-identifier": "names"}},
    ], container="kieq"))
    flat = out["older"]["org.drools.core.runtime.rule.impl.FlatQueryResults"]
    found = [e["value"][f"{PKG}.Customer"]["id"] for row in flat["idResultMaps"]["element"] for e in row["element"]
             if e["key"] == "$c"]
    assert sorted(found) == ["c1", "c2"] and "$c" in flat["identifiers"]["element"]
    assert sorted(out["names"]) == ["c1", "c2"]
    out = results(batch(kie, [{"set-focus": {"name": "night"}}, {"fire-all-rules": {"out-identifier": "n"}},
                              {"get-global": {"identifier": "names"}}], container="kieq"))
    assert out["n"] == 1 and "night c2" in out["names"]  # get-global without out-identifier: keyed by identifier
    out = results(batch(kie, [{"clear-agenda-group": {"name": "night"}}, {"clear-agenda": ""},
                              {"clear-activation-group": {"name": "none"}}], container="kieq"))
    assert out == {}
    dispose(kie, container="kieq")


def test_session_clock_and_temporal_rules(kie, client):
    assert client.put("/api/rulesets/temporal", json={"files": TEMPORAL}).status_code == 201
    visit = lambda vid, ts: {"insert": {"object": {"org.printeps.temporal.Visit": {"id": vid, "ts": ts}}}}
    out = results(batch(kie, [{"get-session-time": ""}], container="temporal"))
    assert out["session-currenttime"] == 0  # a pseudo clock, KIE's default out-identifier
    out = results(batch(kie, [visit("question", 0), {"fire-all-rules": {"out-identifier": "n"}}], container="temporal"))
    assert out["n"] == 0
    out = results(batch(kie, [{"advance-session-time": {"amount": 3, "unit": "SECONDS", "out-identifier": "t"}},
                              {"fire-all-rules": {"out-identifier": "n"}}], container="temporal"))
    assert out["t"] == 3000 and out["n"] == 0  # 3 s: the answer may still come
    out = results(batch(kie, [{"advance-session-time": {"amount": 2001}}, {"fire-all-rules": ""}], container="temporal"))
    assert out["session-advancecurrenttime"] == 5001
    assert [a["params"]["text"] for a in out["actions"]] == ["no answer to question"]
    # a sliding window by the session's clock: three visits within 10 s make a crowd
    dispose(kie, container="temporal")
    out = results(batch(kie, [visit("v1", 0), visit("v2", 1000), {"fire-all-rules": {"out-identifier": "n"}}],
                        container="temporal"))
    assert out["n"] == 0
    out = results(batch(kie, [{"advance-session-time": {"amount": 14, "unit": "SECONDS"}}, visit("v3", 14000),
                              visit("v4", 14000), {"fire-all-rules": {"out-identifier": "n"}}], container="temporal"))
    assert out["n"] == 0  # v1 and v2 slid out of the window: two visits in the last 10 s
    out = results(batch(kie, [visit("v5", 14000), {"fire-all-rules": ""}], container="temporal"))
    assert [a["params"]["text"] for a in out["actions"]] == ["crowd"]
    dispose(kie, container="temporal")


def test_container_lifecycle(kie, client):
    assert client.put("/api/rulesets/life", json={"files": files("L1")}).status_code == 201
    assert client.put("/api/rulesets/life", json={"files": files("L2")}).status_code == 201
    results(batch(kie, [{"insert": {"object": customer("lc", 30)}}], container="life"))
    r = kie.delete(f"{BASE}/containers/life")
    assert r.json() == {"type": "SUCCESS", "msg": "Container life successfully disposed.", "result": None}
    assert kie.get(f"{BASE}/containers/life").json()["type"] == "FAILURE"
    assert client.get("/api/rulesets/life/versions").status_code == 200  # the history stays
    assert kie.delete(f"{BASE}/containers/life").json()["msg"] == "Container life was not instantiated."
    r = kie.put(f"{BASE}/containers/life", json={"container-id": "life", "release-id": {
        "group-id": "org.printeps.rules", "artifact-id": "life", "version": "1"}})
    assert r.status_code == 201, r.text
    assert r.json()["msg"] == "Container life successfully deployed with module org.printeps.rules:life:1."
    assert r.json()["result"]["kie-container"]["release-id"]["version"] == "1"
    out = results(batch(kie, [{"get-objects": {"out-identifier": "o"}}], container="life"))
    assert out["o"] == []  # the session was disposed with the container
    out = results(batch(kie, [{"insert": {"object": customer("lc", 30)}}, {"fire-all-rules": ""}], container="life"))
    assert out["actions"][0]["params"]["text"] == "Welcome lc (L1)"
    assert kie.get(f"{BASE}/containers/life/release-id").json()["result"]["release-id"]["version"] == "1"
    r = kie.post(f"{BASE}/containers/life/release-id", json={"group-id": "org.printeps.rules", "artifact-id": "life",
                                                             "version": "LATEST"})
    assert r.json() == {"type": "SUCCESS", "msg": "Release id successfully updated.",
                        "result": {"release-id": {"group-id": "org.printeps.rules", "artifact-id": "life", "version": "2"}}}
    for body, status, text in (
        ({"container-id": "life", "release-id": {"artifact-id": "life", "version": "1"}}, 400, "already exists"),
        ({"release-id": {"artifact-id": "other", "version": "1"}}, 400, "artifact-id must be the rule set's name"),
        ({"release-id": {"artifact-id": "life", "version": "x"}}, 400, "version number or LATEST"),
    ):
        r = kie.put(f"{BASE}/containers/life", json=body)
        assert r.status_code == status and text in r.json()["msg"], r.text
    r = kie.put(f"{BASE}/containers/never", json={"release-id": {"artifact-id": "never", "version": "1"}})
    assert r.status_code == 400 and "no rule set named never" in r.json()["msg"]
    r = kie.post(f"{BASE}/containers/life/release-id", json={"artifact-id": "life", "version": "9"})
    assert r.status_code == 200 and r.json()["type"] == "FAILURE" and "no such version" in r.json()["msg"]
    dispose(kie, container="life")


def test_live_sessions_follow_deploys_with_their_facts(kie, client):
    assert client.put("/api/rulesets/policy", json={"files": files("P1")}).status_code == 201
    r = batch(kie, [{"insert": {"object": customer("p1", 30), "out-identifier": "p1"}},
                    {"fire-all-rules": {"out-identifier": "n"}}], container="policy")
    assert results(r)["actions"][0]["params"]["text"] == "Welcome p1 (P1)"
    handle = handles(r)["p1"][HANDLE]["external-form"]
    assert client.put("/api/rulesets/policy", json={"files": files("P2")}).status_code == 201
    r = batch(kie, [{"fire-all-rules": {"out-identifier": "n"}}, {"get-object": {"fact-handle": handle, "out-identifier": "p1"}},
                    {"insert": {"object": customer("p2", 40)}}, {"fire-all-rules": {"out-identifier": "m"}}],
              container="policy")
    out = results(r)
    assert r.headers["x-ruleset-version"] == "2"
    # the changed greeting rule sees the fact that came across; "Adult" (unchanged) does not fire again
    assert [a["params"]["text"] for a in out["actions"]] == ["Welcome p1 (P2)", "Welcome p2 (P2)"]
    assert out["n"] == 1 and out["m"] == 2
    assert out["p1"] == {f"{PKG}.Customer": {"id": "p1", "age": 30, "category": "adult"}}  # the old handle still works
    info = client.get("/api/rulesets/policy/sessions/defaultKieSession").json()
    assert info["version"] == 2 and info["moves"][-1]["from"] == 1 and info["moves"][-1]["to"] == 2, info
    # a pinned session stays on its version
    pinned = client.post("/api/rulesets/policy/sessions", json={"on_deploy": "pin", "facts": [
        {"type": "Customer", "id": "q", "age": 50}]}).json()
    assert client.put("/api/rulesets/policy", json={"files": files("P3")}).status_code == 201
    fired = client.post(f"/api/rulesets/policy/sessions/{pinned['id']}/fire").json()
    assert fired["version"] == 2 and [a["params"]["text"] for a in fired["actions"]] == ["Welcome q (P2)"]
    out = results(batch(kie, [{"fire-all-rules": ""}], container="policy"))
    assert [a["params"]["text"] for a in out["actions"]] == ["Welcome p1 (P3)", "Welcome p2 (P3)"]
    client.delete(f"/api/rulesets/policy/sessions/{pinned['id']}")
    dispose(kie, container="policy")
