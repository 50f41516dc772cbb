"""``/api/rulesets/{name}/sessions``: stateful sessions over REST on a real gateway (JVM + Drools +
Information State): create, list, read facts, insert/modify/update/retract by handle, fire with
``max`` (recorded decisions), the session clock with a temporal rule and a sliding window,
dispose, limits and the idle TTL, the kmodule.xml declarations, and validate = deploy's body."""

from __future__ import annotations

import time

import pytest
from api_helpers import files
from test_kie_server import BASE, TEMPORAL

PREFIX = "/api/rulesets/rs"


@pytest.fixture(scope="module")
def rs(client):
    assert client.put("/api/rulesets/rs", json={"files": files("S1")}).status_code == 201
    yield client


def test_create_insert_fire_read_retract_dispose(rs, api_gateway):
    r = rs.post(f"{PREFIX}/sessions", json={"facts": [{"type": "Customer", "id": "a", "age": 30}]})
    assert r.status_code == 201, r.text
    session = r.json()
    sid = session["id"]
    assert session["version"] == 1 and session["clock"] == "pseudo" and session["on_deploy"] == "follow"
    assert session["fact_count"] == 1 and len(session["handles"]) == 1
    assert r.headers["location"] == f"{PREFIX}/sessions/{sid}"
    listed = rs.get(f"{PREFIX}/sessions").json()
    assert sid in [s["id"] for s in listed["sessions"]]
    assert [d["name"] for d in listed["declared"]] == ["defaultKieSession", "defaultStatelessKieSession"]
    inserted = rs.post(f"{PREFIX}/sessions/{sid}/facts", json={"facts": [{"type": "Customer", "id": "b", "age": 8},
                                                                     {"type": "Customer", "id": "c", "age": 50}]})
    assert inserted.status_code == 201 and inserted.json()["fact_count"] == 3
    handle_b, handle_c = inserted.json()["handles"]
    fired = rs.post(f"{PREFIX}/sessions/{sid}/fire", json={"max": 1}).json()
    assert fired["fire_count"] == 1 and fired["decision_id"] and fired["session"] == sid
    fired = rs.post(f"{PREFIX}/sessions/{sid}/fire").json()
    assert sorted(a["params"]["text"] for a in fired["actions"]) == ["Welcome a (S1)", "Welcome c (S1)"]
    api_gateway.store.flush()
    decision = rs.get(f"/api/decisions/{fired['decision_id']}").json()
    assert decision["origin"] == "rest" and decision["context"]["session"] == sid
    modified = rs.patch(f"{PREFIX}/sessions/{sid}/facts/{handle_b}", json={"set": {"age": 19}})
    assert modified.json()["fact"] == {"type": "Customer", "id": "b", "age": 19, "category": None}
    fired = rs.post(f"{PREFIX}/sessions/{sid}/fire").json()
    assert [a["params"]["text"] for a in fired["actions"]] == ["Welcome b (S1)"]
    replaced = rs.put(f"{PREFIX}/sessions/{sid}/facts/{handle_c}", json={"fact": {"type": "Customer", "id": "c2", "age": 5}})
    assert replaced.json()["fact"]["id"] == "c2"
    facts = rs.get(f"{PREFIX}/sessions/{sid}/facts", params={"type": "Customer"}).json()
    assert sorted(f["fact"]["id"] for f in facts["facts"]) == ["a", "b", "c2"]
    # the same fact handle (id, identity): Drools' recency field moved with the modify
    assert handle_b.split(":")[:3] in [f["handle"].split(":")[:3] for f in facts["facts"]]
    assert rs.delete(f"{PREFIX}/sessions/{sid}/facts/{handle_b}").json()["fact_count"] == 2
    stale = rs.delete(f"{PREFIX}/sessions/{sid}/facts/{handle_b}")
    assert stale.status_code == 422 and stale.json()["problem"] == "handle" and "not in this session" in stale.json()["error"]
    bad = rs.post(f"{PREFIX}/sessions/{sid}/facts", json={"facts": [{"type": "Customer", "id": "ok", "age": 1},
                                                               {"type": "Customer", "id": "bad", "age": "x"}]})
    assert bad.status_code == 422 and "object 1" in bad.json()["error"] and bad.json()["field"] == "age"
    assert rs.get(f"{PREFIX}/sessions/{sid}").json()["fact_count"] == 2  # nothing of the refused insert
    both = rs.post(f"{PREFIX}/sessions/{sid}/facts", json={"facts": [{"type": "Customer", "id": "d", "age": 70}], "fire": True})
    assert both.status_code == 201 and both.json()["fact_count"] == 3 and both.json()["decision_id"]
    assert [a["params"]["text"] for a in both.json()["actions"]] == ["Welcome d (S1)"]
    assert rs.delete(f"{PREFIX}/sessions/{sid}/facts/{both.json()['handles'][0]}").json()["fact_count"] == 2
    assert rs.delete(f"{PREFIX}/sessions/{sid}").json() == {"id": sid, "ruleset": "rs", "disposed": True}
    assert rs.get(f"{PREFIX}/sessions/{sid}").status_code == 404
    assert rs.post(f"{PREFIX}/sessions/{sid}/fire").status_code == 404


def test_the_kie_session_is_the_rest_session(rs, live_server):
    import httpx

    with httpx.Client(base_url=live_server.url, timeout=30) as kie:
        r = kie.post(f"{BASE}/containers/instances/rs", json={"lookup": "defaultKieSession", "commands": [
            {"insert": {"object": {"org.printeps.apitest.Customer": {"id": "k", "age": 40}}, "out-identifier": "k"}}]})
        handle = r.json()["result"]["execution-results"]["facts"][0]["value"][
            "org.drools.core.common.DefaultFactHandle"]["external-form"]
    facts = rs.get(f"{PREFIX}/sessions/defaultKieSession/facts").json()["facts"]
    assert [(f["handle"], f["fact"]["id"]) for f in facts] == [(handle, "k")]
    again = rs.post(f"{PREFIX}/sessions", json={"id": "defaultKieSession"})
    assert again.status_code == 200 and again.json()["fact_count"] == 1  # the same live session
    assert rs.post(f"{PREFIX}/sessions", json={"id": "defaultStatelessKieSession"}).status_code == 422
    rs.delete(f"{PREFIX}/sessions/defaultKieSession")


def test_clock_temporal_rule_and_sliding_window(client):
    assert client.put("/api/rulesets/rtemporal", json={"files": TEMPORAL}).status_code == 201
    base = "/api/rulesets/rtemporal/sessions"
    sid = client.post(base, json={}).json()["id"]
    client.post(f"{base}/{sid}/facts", json={"facts": [{"type": "Visit", "id": "question", "ts": 1_000}], "timestamp": 1_000})
    assert client.post(f"{base}/{sid}/fire").json()["actions"] == []
    assert client.post(f"{base}/{sid}/advance", json={"ms": 4_000}).json()["time"] == 5_000
    assert client.post(f"{base}/{sid}/fire").json()["actions"] == []  # within after[0s, 5s]
    advanced = client.post(f"{base}/{sid}/advance", json={"to": 6_001, "fire": True}).json()
    assert advanced["time"] == 6_001 and [a["params"]["text"] for a in advanced["actions"]] == ["no answer to question"]
    # window:time(10s) by the session's clock
    client.post(f"{base}/{sid}/facts", json={"facts": [{"type": "Visit", "id": "v1", "ts": 20_000}], "timestamp": 20_000})
    client.post(f"{base}/{sid}/facts", json={"facts": [{"type": "Visit", "id": "v2", "ts": 25_000}], "timestamp": 25_000})
    assert client.post(f"{base}/{sid}/fire").json()["actions"] == []
    client.post(f"{base}/{sid}/facts", json={"facts": [{"type": "Visit", "id": "v3", "ts": 31_000}], "timestamp": 31_000})
    assert client.post(f"{base}/{sid}/fire").json()["actions"] == []  # v1 slid out at 30 s
    client.post(f"{base}/{sid}/facts", json={"facts": [{"type": "Visit", "id": "v4", "ts": 32_000}], "timestamp": 32_000})
    assert [a["params"]["text"] for a in client.post(f"{base}/{sid}/fire").json()["actions"]] == ["crowd"]
    bad = client.post(f"{base}/{sid}/advance", json={"ms": 1, "to": 2})
    assert bad.status_code == 422
    realtime = client.post(base, json={"clock": "realtime"}).json()
    assert realtime["clock"] == "realtime" and realtime["time"] > 1_600_000_000_000
    refused = client.post(f"{base}/{realtime['id']}/advance", json={"ms": 5})
    assert refused.status_code == 422 and "realtime" in refused.json()["error"]
    for s in (sid, realtime["id"]):
        client.delete(f"{base}/{s}")


def test_kmodule_declares_sessions(client):
    kfiles = files("KM")
    kfiles["kmodule.xml"] = """<kmodule xmlns="http://www.drools.org/xsd/kmodule">
  <kbase name="rules">
    <ksession name="front-desk" default="true" clockType="pseudo" onDeploy="pin"/>
    <ksession name="quick" type="stateless"/>
  </kbase>
</kmodule>"""
    assert client.put("/api/rulesets/km", json={"files": kfiles}).status_code == 201
    declared = client.get("/api/rulesets/km/sessions").json()["declared"]
    assert [(d["name"], d["type"], d["clock"], d["on_deploy"]) for d in declared] == [
        ("front-desk", "stateful", "pseudo", "pin"), ("quick", "stateless", "realtime", None)]
    session = client.get("/api/rulesets/km/sessions/front-desk").json()  # made on first use, like a lookup
    assert session["on_deploy"] == "pin" and session["kind"] == "kie"
    assert client.get("/api/rulesets/km/sessions/defaultKieSession").status_code == 404  # declared sessions only
    client.delete("/api/rulesets/km/sessions/front-desk")
    broken = dict(kfiles)
    broken["kmodule.xml"] = '<kmodule>\n  <kbase>\n    <ksession name="a" type="statefull"/>\n  </kbase>\n</kmodule>'
    r = client.post("/api/rulesets/km/validate", json={"files": broken})
    assert r.json()["ok"] is False
    assert r.json()["errors"] == [{"file": "kmodule.xml", "line": 3, "column": 5,
                                   "message": "ksession 'a': type must be stateful or stateless, not 'statefull'"}]
    r = client.put("/api/rulesets/km", json={"files": {**kfiles, "kmodule.xml": "<kmodule><kbase>"}})
    assert r.status_code == 422 and r.json()["errors"][0]["file"] == "kmodule.xml"


def test_validate_accepts_exactly_the_deploy_body(client):
    body = {"files": files("V"), "comment": "what I am about to deploy", "base_version": 0, "force": False}
    r = client.post("/api/rulesets/validated/validate", json=body)
    assert r.status_code == 200 and r.json() == {"ok": True, "errors": []}
    assert client.put("/api/rulesets/validated", json=body).status_code == 201
    assert client.post("/api/rulesets/validated/validate", json={**body, "extra": 1}).status_code == 422


def test_limits_and_idle_ttl(api_gateway, client):
    manager = api_gateway.engine.session_manager
    settings = manager.settings
    saved = (settings.max_per_ruleset, settings.max_facts, settings.idle_ttl_s)
    assert client.put("/api/rulesets/lim", json={"files": files("LIM")}).status_code == 201
    try:
        settings.max_per_ruleset, settings.max_facts = 2, 3
        a = client.post("/api/rulesets/lim/sessions", json={}).json()["id"]
        client.post("/api/rulesets/lim/sessions", json={})
        third = client.post("/api/rulesets/lim/sessions", json={})
        assert third.status_code == 429 and "at most 2" in third.json()["error"]
        facts = [{"type": "Customer", "id": f"f{k}", "age": 1} for k in range(4)]
        over = client.post(f"/api/rulesets/lim/sessions/{a}/facts", json={"facts": facts})
        assert over.status_code == 429 and "limit of 3" in over.json()["error"]
        settings.idle_ttl_s = 0.2
        time.sleep(0.3)
        assert a in manager.reap()
        assert client.get(f"/api/rulesets/lim/sessions/{a}").status_code == 404
        assert "idle longer than" in client.get(f"/api/rulesets/lim/sessions/{a}").json()["error"]
    finally:
        settings.max_per_ruleset, settings.max_facts, settings.idle_ttl_s = saved
        manager.dispose_ruleset("lim")


def test_deleting_the_rule_set_disposes_its_sessions(client):
    assert client.put("/api/rulesets/gone", json={"files": files("G")}).status_code == 201
    sid = client.post("/api/rulesets/gone/sessions", json={}).json()["id"]
    assert client.delete("/api/rulesets/gone").status_code == 200
    assert client.get(f"/api/rulesets/gone/sessions/{sid}").status_code == 404
