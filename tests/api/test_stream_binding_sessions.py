"""A stateful stream binding's session is a durable session (issue 28 item 4), in one real gateway
(JVM + Drools + Information State): it has the stable id ``stream.<query>``; each window's fire is
journalled; lost from its process (as a crash loses it) it is rebuilt at the binding's next fire
with its facts and clock, and what fired does not fire again; the engine's clean close keeps its
log; it is never idle-reaped; removing the binding disposes it and deletes its log. The restart of
a real ``printeps serve`` is in tests/cluster/test_stream_binding_durable.py."""

from __future__ import annotations

import pytest
from gw_testing import wait_for

from gateway.runtime.session_log import LOG
from gateway.stream.subscriber import binding_session_id

STREAM = "http://example.org/tanks"
DRL = """package org.printeps.tanks;
import org.printeps.gateway.Actions;
global Actions actions;
declare Level
    id : String
    value : int
end
rule "Note a level"
when
    $l : Level()
then
    actions.say("pepper", "level " + $l.getId());
end
"""
QUERY = """REGISTER QUERY TankLevels AS
PREFIX ex: <http://example.org/>
SELECT ?s ?value
FROM STREAM <http://example.org/tanks> [RANGE 1s STEP 1s]
WHERE { ?s ex:value ?value }"""
BINDING = {"ruleset": "tanks", "fact_type": "Level", "fields": {"id": "s", "value": "value"}, "mode": "stateful"}
SID = "stream.TankLevels"
SESSION = f"/api/rulesets/tanks/sessions/{SID}"


@pytest.fixture(scope="module")
def tanks(client, api_gateway):
    assert client.put("/api/rulesets/tanks", json={"files": {"tanks.drl": DRL}}).status_code == 201
    r = client.post("/api/queries", json={"query": QUERY, "rules": BINDING})
    assert r.status_code == 201, r.text
    yield client
    client.delete("/api/queries/TankLevels")


def _post(client, ts: int, tank: str | None = None) -> None:
    triples = [[f"<http://example.org/{tank}>", "<http://example.org/value>", ts]] if tank else []
    r = client.post("/api/streams", json={"stream": STREAM, "timestamp": ts, "triples": triples})
    assert r.status_code == 200, r.text


def _levels(client) -> list[str] | None:
    r = client.get(f"{SESSION}/facts")
    return None if r.status_code == 404 else sorted(f["fact"]["id"] for f in r.json()["facts"])


def _said(gateway) -> list[str]:
    gateway.store.flush()
    found, _ = gateway.decisions.find(ruleset="tanks", origin="stream", limit=100)
    return sorted(a["params"]["text"] for d in found for a in d.get("actions", []))


def test_the_session_id_is_stable_and_safe():
    assert binding_session_id("TankLevels") == SID
    assert binding_session_id("a b/c") == "stream.a_b_c"


def test_a_lost_binding_session_is_rebuilt_at_the_next_fire(tanks, api_gateway):
    _post(tanks, 500, "t1")
    _post(tanks, 1500, "t2")  # the window ending at 1000 fires t1
    _post(tanks, 2500)  # the one ending at 2000 fires t2
    assert wait_for(lambda: _levels(tanks) == ["t1", "t2"], 30)
    info = tanks.get(SESSION).json()
    assert info["durable"] is True and info["kind"] == "stream" and info["time"] == 2000, info
    api_gateway.store.flush()
    assert api_gateway.store.db[LOG].count_documents({"session": SID, "kind": "batch"}) == 2  # one per window

    manager = api_gateway.engine.session_manager
    session = manager._sessions.pop(("tanks", SID))  # what a killed process leaves: log and record kept
    session._java.dispose()
    session.closed = True
    _post(tanks, 3500, "t3")
    _post(tanks, 4500)  # the binding's next fire rebuilds the session from its log
    assert wait_for(lambda: _levels(tanks) == ["t1", "t2", "t3"], 30)
    assert tanks.get(SESSION).json()["time"] == 4000
    assert wait_for(lambda: _said(api_gateway) == ["level t1", "level t2", "level t3"], 30), _said(api_gateway)

    settings = manager.settings  # never idle-reaped: it lives as long as its binding
    manager.settings = settings.model_copy(update={"idle_ttl_s": 0.01})
    try:
        manager.put_away("tanks", SID)  # as a clean stop does: closed here, its log kept
        assert SID not in manager.reap_stored()
    finally:
        manager.settings = settings
    assert _levels(tanks) == ["t1", "t2", "t3"]  # rebuilt by the read

    assert tanks.delete("/api/queries/TankLevels/rules").status_code == 200  # the binding goes: so does its session
    assert wait_for(lambda: tanks.get(SESSION).status_code == 404, 30)
    assert wait_for(lambda: api_gateway.store.db[LOG].count_documents({"session": SID}) == 0, 30)
