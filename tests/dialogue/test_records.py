"""Where conversations are kept between turns (``gateway.dialogue.records``): the same
compare-and-set in the Information State and in memory, an order whose process died before
keeping it kept by another's watcher, and a turn refused (nothing changed) while the database is
away."""

from __future__ import annotations

import time

import pytest
from pymongo import MongoClient

from gateway.dialogue.records import MemoryConversations, MongoConversations, RecordsUnavailable
from gateway.dialogue.service import DialogueBusy, DialogueService
from gateway.store.shipper import mongo_client
from gw_testing import wait_for


@pytest.fixture(params=["mongo", "memory"])
def records(request, mongo):
    if request.param == "memory":
        yield MemoryConversations()
        return
    client = MongoClient(mongo.uri)
    name = f"records_{time.monotonic_ns()}"
    yield MongoConversations(client[name])
    client.drop_database(name)
    client.close()


def record(rev: int, **extra) -> dict:
    return {"_id": "t1", "generation": "g1", "rev": rev, "going_on": True, "table": "t1", "state": "ordering",
            "turn": rev, "decisions": [], "last_turn_at": 10.0, "last_silence_at": 10.0, **extra}


def test_a_change_is_written_only_over_the_rev_it_read(records):
    assert records.save(record(1), None)
    assert not records.save(record(1), None)  # a second first turn lost: it runs again on this one
    assert records.save(record(2), 1, {"rev": 2, "turn": 2})
    assert not records.save(record(2, turn=9), 1, {"rev": 2, "turn": 9})  # read rev 1, someone wrote rev 2
    assert records.load("t1")["turn"] == 2


def test_notes_survive_the_next_turns_write(records):
    records.save(record(1), None)
    records.note("t1", "g1", {"last_decision_id": "d1", "order_kept": True}, "d1")
    records.note("t1", "other-generation", {"last_decision_id": "x"}, "x")  # an older conversation's late note
    records.save(record(2), 1, {"rev": 2, "turn": 2})
    kept = records.load("t1")
    assert (kept["decisions"], kept["last_decision_id"], kept["order_kept"]) == (["d1"], "d1", True)


def test_the_watchers_queries(records):
    records.save(record(1, order_kept=False, order_at=5.0), None)
    assert [d["_id"] for d in records.quiet(10.0)] == ["t1"] and records.quiet(9.0) == []
    assert [d["_id"] for d in records.stale(10.0)] == ["t1"] and records.stale(9.0) == []
    assert [d["_id"] for d in records.unkept_orders(6.0)] == ["t1"] and records.unkept_orders(4.0) == []
    assert records.count_going_on() == 1 and records.finished(10) == []


def test_an_order_confirmed_by_a_process_that_died_before_keeping_it_is_kept_by_another(gateway):
    d = gateway.dialogue
    d.turn("orphan1", text="two coffees")
    doc = d.records.load("orphan1")
    # what the confirming turn wrote before its process was killed: the order, not yet kept
    died = {"rev": doc["rev"] + 1, "going_on": False, "state": "ordered", "ended_at": time.time() - 60,
            "order": {"table": "orphan1", "drink": "coffee", "cups": 2}, "order_kept": False,
            "order_at": time.time() - 60, "process": "elsewhere:1"}
    heard = []
    d.add_order_listener(heard.append)
    assert d.records.save({**doc, **died}, doc["rev"], died)
    d.check_silences()  # and the gateway's own watcher meanwhile: one of them keeps it
    assert wait_for(lambda: heard and d.records.load("orphan1")["order_kept"] is True, 20)
    d.check_silences()
    assert [(o["conversation"], o["drink"], o["cups"]) for o in heard] == [("orphan1", "coffee", 2)]  # kept once
    assert gateway.store.flush()
    assert wait_for(lambda: gateway.store.query("orders", filters={"conversation": "orphan1"}), 20)
    (stored,) = gateway.store.query("orders", filters={"conversation": "orphan1"})
    assert stored["decision_ids"] == doc["decisions"] and stored["drinks"] == "coffees"


def test_a_turn_while_the_information_state_is_away_is_refused_and_changes_nothing(gateway):
    client = mongo_client("mongodb://127.0.0.1:9/", 200)  # nothing listens on port 9
    away = DialogueService(gateway.engine, gateway.knowledge, gateway.dialogue.settings,
                           records=MongoConversations(client["nowhere"]))
    try:
        with pytest.raises(DialogueBusy) as refused:
            away.turn("away1", text="two coffees")
        assert refused.value.status == 503 and "unreachable" in str(refused.value)
        assert gateway.engine.session_manager.find("dialogue", "dialogue.away1") is None
        with pytest.raises(RecordsUnavailable):  # the route answers 503 + Retry-After
            away.conversations()
    finally:
        away.close()
        client.close()


def test_a_new_conversation_at_the_table_keeps_the_unkept_order_it_replaces(gateway):
    d = gateway.dialogue
    d.turn("orphan2", text="one matcha")
    doc = d.records.load("orphan2")
    died = {"rev": doc["rev"] + 1, "going_on": False, "state": "ordered", "ended_at": time.time(),
            "order": {"table": "orphan2", "drink": "matcha", "cups": 1}, "order_kept": False,
            "order_at": time.time(), "process": "elsewhere:1"}  # just now: no watcher would keep it yet
    heard = []
    d.add_order_listener(heard.append)
    assert d.records.save({**doc, **died}, doc["rev"], died)
    fresh = d.turn("orphan2", text="coffee")
    assert fresh["turn"] == 1 and fresh["state"] == "ordering"
    assert [(o["conversation"], o["drink"], o["cups"]) for o in heard] == [("orphan2", "matcha", 1)]


def test_one_keeper_claims_an_order(records):
    records.save(record(1, order_kept=False, order_at=5.0), None)
    assert not records.claim_order("t1", "other-generation", 0.0)
    assert records.claim_order("t1", "g1", 0.0)
    assert not records.claim_order("t1", "g1", 0.0)  # being kept by a recent claim
    assert records.unkept_orders(0.0) == []
    later = time.time() + 1
    assert [d["_id"] for d in records.unkept_orders(later)] == ["t1"]  # its keeper never finished
    assert records.claim_order("t1", "g1", later)  # so another takes it over
    records.note("t1", "g1", {"order_kept": True})
    assert not records.claim_order("t1", "g1", later) and records.unkept_orders(later) == []


def test_a_conversation_whose_kept_facts_the_live_rules_refuse_starts_anew(gateway):
    d = gateway.dialogue
    d.turn("unfit1", text="coffee")
    doc = d.records.load("unfit1")
    # as if an owner's deploy had removed a type the conversation kept (written by another process)
    unfit = {"rev": doc["rev"] + 1, "facts": [{"type": "Reservation", "id": "r1", "table": "t1"}]}
    assert d.records.save({**doc, **unfit}, doc["rev"], unfit)
    answer = d.turn("unfit1", text="two coffees")
    assert answer["turn"] == 1 and answer["slots"] == {"drink": "coffee", "cups": 2}
    assert d.records.load("unfit1")["generation"] != doc["generation"]
