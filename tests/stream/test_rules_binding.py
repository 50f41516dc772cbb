"""Detections become facts of a rule set and the rules fire (real Drools in the JVM)."""

from __future__ import annotations

import pytest
from csparql_scenarios import (
    CUSTOMER_QUERY,
    approaching,
    messages,
    replay,
    walking_past,
)

from gateway.config import Settings
from gateway.engine import Engine
from gateway.stream import BindingError, RuleBinding, StreamEngine

DRL = """package org.printeps.detect;
import org.printeps.gateway.Actions;
global Actions actions;

declare CustomerEntered
    @role(event)
    id : String
    count : int
    distance : double
end

rule "greet a customer who entered"
when
    $c : CustomerEntered(distance < 3.3)
then
    actions.say("pepper", "Welcome, " + $c.getId());
end

declare TableLeft
    table : String
    lastSeen : long
end

rule "clear a table its customers left"
when
    $t : TableLeft()
then
    actions.call("workflow", "name", "clear_table", "table", $t.getTable());
end

declare HotThing
    id : String
    hot : int
end

rule "report a hot thing"
when
    $h : HotThing(hot > 30)
then
    actions.say("pepper", $h.getId() + " is hot");
end
"""


@pytest.fixture(scope="module")
def rules_engine(tmp_path_factory) -> Engine:
    base = tmp_path_factory.mktemp("rules")
    engine = Engine(Settings(data_dir=str(base / "data"), engine={"rules_dir": str(base / "drl")}))
    engine.deploy("detect", {"detect.drl": DRL}, author="test")
    return engine


@pytest.mark.parametrize("mode", ["stateless", "stateful"])
def test_detections_fire_the_rules(settings, rules_engine, mode):
    engine = StreamEngine(settings, rules_engine=rules_engine)
    binding = RuleBinding("detect", "CustomerEntered", {"id": "s", "count": "cnt", "distance": "distance"}, mode=mode)
    engine.register(CUSTOMER_QUERY, binding=binding)
    events: list[dict] = []
    engine.subscribe(events.append)
    replay(engine, messages({"c1": approaching(4.0, 0.3), "c2": walking_past(2.0)}, hz=1, seconds=6, t0_ms=500))
    actions = [e for e in events if e["kind"] == "actions"]
    # detections in the windows ending 4000 and 5000 (see test_customer_detection)
    assert [a["window"]["end"] for a in actions] == [4000, 5000]
    first = actions[0]
    assert first["facts"] == [{"type": "CustomerEntered", "id": "c1", "count": 3, "distance": 3.2}]
    assert [(a["module"], a["params"]) for a in first["actions"]] == [("say", {"robot": "pepper", "text": "Welcome, c1"})]
    assert engine.query_info("CustomerDetectionQuery")["stats"]["rule_fires"] == 2
    engine.close()


def test_bad_bindings_are_refused(settings, rules_engine):
    engine = StreamEngine(settings, rules_engine=rules_engine)
    engine.register(CUSTOMER_QUERY)
    name = "CustomerDetectionQuery"
    with pytest.raises(BindingError, match="declares no type 'Nope'"):
        engine.bind_rules(name, RuleBinding("detect", "Nope"))
    with pytest.raises(BindingError, match="no field 'age'"):
        engine.bind_rules(name, RuleBinding("detect", "CustomerEntered", {"age": "cnt"}))
    with pytest.raises(BindingError, match="no variable \\?x"):
        engine.bind_rules(name, RuleBinding("detect", "CustomerEntered", {"id": "x"}))
    with pytest.raises(Exception, match="nope"):
        engine.bind_rules(name, RuleBinding("nope", "CustomerEntered"))
    # default fields: variables named like fields (only "distance" here)
    info = engine.bind_rules(name, RuleBinding("detect", "CustomerEntered"))
    assert info["binding"]["fields"] == {"distance": "distance"}


def test_leaving_seat_fires_the_clear_table_rules(settings, rules_engine):
    from table_scenarios import LEAVING_SEAT_QUERY
    from table_scenarios import messages as table_messages
    from table_scenarios import replay as table_replay

    engine = StreamEngine(settings, rules_engine=rules_engine)
    engine.register(LEAVING_SEAT_QUERY,
                    binding=RuleBinding("detect", "TableLeft", {"table": "table", "lastSeen": "last_seen"}))
    events: list[dict] = []
    engine.subscribe(events.append)
    table_replay(engine, table_messages({"table2": [("c1", "Customer", 0, 10)]}, ["table2"], hz=2, seconds=40))
    (fired,) = [e for e in events if e["kind"] == "actions"]
    assert fired["window"]["end"] == 30_000
    assert fired["facts"] == [{"type": "TableLeft", "table": "table2", "lastSeen": 9_500}]
    assert [(a["module"], a["params"]) for a in fired["actions"]] == [
        ("workflow", {"name": "clear_table", "table": "table2"})]
    engine.close()


def test_rules_bound_to_a_derived_stream(settings, rules_engine):
    from pyoxigraph import Literal, NamedNode

    from gateway.rdf.terms import XSD_INTEGER

    engine = StreamEngine(settings, rules_engine=rules_engine)
    engine.register("REGISTER STREAM ex:hot AS PREFIX ex: <http://ex/>\nCONSTRUCT { ?s ex:hot ?v } "
                    "FROM STREAM <http://ex/raw> [RANGE 1s STEP 1s] WHERE { ?s ex:temp ?v FILTER(?v > 30) }")
    # a stream's facts: one per subject, its predicates' local names as fields (here: subject, hot)
    info = engine.bind_rules("ex:hot", RuleBinding("detect", "HotThing", {"id": "subject", "hot": "hot"}))
    assert info["binding"]["fields"] == {"id": "subject", "hot": "hot"}
    with pytest.raises(BindingError, match="no variable \\?temp"):
        engine.bind_rules("ex:hot", RuleBinding("detect", "HotThing", {"hot": "temp"}))
    engine.bind_rules("ex:hot", RuleBinding("detect", "HotThing", {"id": "subject", "hot": "hot"}))
    events: list[dict] = []
    engine.subscribe(events.append)
    engine.push("http://ex/raw", 100, [(NamedNode("http://ex/a"), NamedNode("http://ex/temp"),
                                        Literal("35", datatype=XSD_INTEGER))])
    engine.advance(1000)
    (fired,) = [e for e in events if e["kind"] == "actions"]
    assert fired["facts"] == [{"type": "HotThing", "id": "a", "hot": 35}]
    assert [a["params"] for a in fired["actions"]] == [{"robot": "pepper", "text": "a is hot"}]
    engine.close()


SLOW_DRL = """package org.printeps.slowdetect;
import org.printeps.gateway.Actions;
global Actions actions;
declare CustomerEntered
    id : String
    count : int
    distance : double
end
rule "Welcome, when the gate opens"
when
    $c : CustomerEntered()
then
    String gate = System.getProperty("printeps.test.gate");
    if (gate != null) {  // only in the test: the deploy's warm-up fires made-up facts without it
        try { new java.io.File(gate + ".started").createNewFile(); } catch (Exception e) { }
        long deadline = System.currentTimeMillis() + 120000;
        while (!new java.io.File(gate).exists() && System.currentTimeMillis() < deadline) {
            try { Thread.sleep(5); } catch (InterruptedException e) { }
        }
    }
    actions.say("pepper", "Welcome, " + $c.getId());
end
"""


def test_a_slow_binding_skips_windows_and_never_holds_up_the_stream(settings, rules_engine, tmp_path):
    """Ten windows detect customers while the binding's first fire is blocked: the stream goes on
    (it waited only streams.binding_wait_s, once), the windows in between are reported skipped, the
    newest waits; when the gate opens, the first and the newest fire and report themselves."""
    import time

    import jpype

    from gw_testing import wait_for

    rules_engine.deploy("slowdetect", {"slow.drl": SLOW_DRL}, author="test")
    gate = tmp_path / "gate"
    system = jpype.JClass("java.lang.System")
    system.setProperty("printeps.test.gate", str(gate))
    engine = StreamEngine(settings.model_copy(update={"binding_wait_s": 0.2}), rules_engine=rules_engine)
    try:
        binding = RuleBinding("slowdetect", "CustomerEntered", {"id": "s", "count": "cnt", "distance": "distance"})
        engine.register(CUSTOMER_QUERY, binding=binding)
        events: list[dict] = []
        engine.subscribe(events.append)
        tracks = {"c1": approaching(4.0, 0.3), "c2": approaching(5.0, 0.3), "c3": approaching(6.0, 0.3)}
        t0 = time.monotonic()
        replay(engine, messages(tracks, hz=1, seconds=14, t0_ms=500))
        assert time.monotonic() - t0 < 30.0  # the blocked fire (up to 120 s) did not hold the stream
        assert (tmp_path / "gate.started").exists() and not [e for e in events if e["kind"] == "actions"]
        skipped = [e["window"]["end"] for e in events if e["kind"] == "skipped"]
        assert skipped == list(range(5000, 13000, 1000)), skipped
        assert all(e["ruleset"] == "slowdetect" and "binding_wait_s" in e["reason"] for e in events
                   if e["kind"] == "skipped")
        gate.touch()
        assert wait_for(lambda: len([e for e in events if e["kind"] == "actions"]) == 2, 60), events[-3:]
        actions = [e for e in events if e["kind"] == "actions"]
        assert [a["window"]["end"] for a in actions] == [4000, 13000] and all(a["late"] for a in actions)
        assert actions[1]["actions"][0]["params"]["text"] == "Welcome, c1"
        stats = engine.query_info("CustomerDetectionQuery")["stats"]
        assert stats["rule_skipped"] == 8 and stats["rule_fires"] == 2
    finally:
        gate.touch()
        system.clearProperty("printeps.test.gate")
        engine.close()


def test_a_binding_fires_outside_the_stream_lock(settings, rules_engine, tmp_path):
    """While a binding's fire runs (blocked in its then-part, well within streams.binding_wait_s),
    the stream engine stays usable from another thread: its queries can be read and messages pushed.
    (When the fire ran under the stream lock, both waited for the fire.) When the fire ends, the
    pushing thread publishes its actions in time, not late."""
    import threading
    import time

    import jpype

    from gw_testing import wait_for

    rules_engine.deploy("slowdetect", {"slow.drl": SLOW_DRL}, author="test")
    gate = tmp_path / "gate"
    system = jpype.JClass("java.lang.System")
    system.setProperty("printeps.test.gate", str(gate))
    engine = StreamEngine(settings.model_copy(update={"binding_wait_s": 120.0}), rules_engine=rules_engine)
    pusher: threading.Thread | None = None
    try:
        binding = RuleBinding("slowdetect", "CustomerEntered", {"id": "s", "count": "cnt", "distance": "distance"})
        engine.register(CUSTOMER_QUERY, binding=binding)
        events: list[dict] = []
        engine.subscribe(events.append)
        first = list(messages({"c1": approaching(4.0, 0.3)}, hz=1, seconds=5, t0_ms=500))  # closes 1000..4000
        pusher = threading.Thread(target=replay, args=(engine, first), daemon=True)
        pusher.start()
        assert wait_for(lambda: (tmp_path / "gate.started").exists(), 60)  # the fire is in flight
        started = time.monotonic()
        assert engine.query_info("CustomerDetectionQuery")["stats"]["results"] >= 1
        replay(engine, [(4700, first[-1][1])])  # a message within the open window: no fire of its own
        assert time.monotonic() - started < 10.0 and pusher.is_alive()  # the fire is still blocked
        gate.touch()
        pusher.join(60)
        assert not pusher.is_alive()
        actions = [e for e in events if e["kind"] == "actions"]
        assert actions and not actions[0].get("late") and actions[0]["window"]["end"] == 4000
    finally:
        gate.touch()
        system.clearProperty("printeps.test.gate")
        if pusher is not None:
            pusher.join(60)
        engine.close()
