"""The Information State against a real MongoDB-protocol server: record, query, bad input, outages."""

from __future__ import annotations

import math
import threading
import time
from datetime import datetime, timedelta, timezone

import pymongo
import pytest
from gw_testing import wait_for

from gateway.store import StoreError, open_store
from gateway.store.store import InformationState


def test_record_has_meta_and_query_by_type_time_and_fields(store: InformationState) -> None:
    t0 = datetime.now(timezone.utc)
    store.record("actions", {"robot": "pepper", "module": "say", "text": "Welcome."},
                 stored_type="printeps/Action", inserted_by="test")
    store.record("actions", {"robot": "hsr", "module": "move"}, stored_type="printeps/Action", inserted_by="test")
    store.record("actions", {"robot": "pepper", "note": "x"}, stored_type="printeps/Other", inserted_by="test")
    assert store.flush()  # writes are journalled first, then shipped
    docs = store.query("actions", type="printeps/Action")
    assert {d["robot"] for d in docs} == {"pepper", "hsr"}
    meta = docs[0]["_meta"]
    assert meta["stored_type"] == "printeps/Action" and meta["inserted_by"] == "test"
    assert meta["inserted_at"] >= t0 - timedelta(seconds=1)
    assert [d["text"] for d in store.query("actions", filters={"robot": "pepper", "module": "say"})] == ["Welcome."]
    assert store.query("actions", since=datetime.now(timezone.utc) + timedelta(seconds=5)) == []
    assert len(store.query("actions", since=t0 - timedelta(seconds=1), until=datetime.now(timezone.utc)
                           + timedelta(seconds=1))) == 3
    assert store.health()["status"] == "ok"


def test_nested_filters_and_newest_first(store: InformationState) -> None:
    for i in range(3):
        store.record("rule_firings", {"ruleset": "reception", "result": {"count": i}}, stored_type="printeps/Firing")
    assert store.flush()
    docs = store.query("rule_firings", filters={"result.count": 2})
    assert len(docs) == 1
    assert [d["result"]["count"] for d in store.query("rule_firings")] == [2, 1, 0]


@pytest.mark.parametrize("call, message", [
    (lambda s: s.record("bad name", {}, stored_type="x"), "collection 'bad name'"),
    (lambda s: s.record("actions", {"$where": 1}, stored_type="x"), "field name '$where'"),
    (lambda s: s.record("actions", {"a": {"b.c": 1}}, stored_type="x"), "actions.a: field name 'b.c'"),
    # after values that look like keys to a naive search (escaped quotes, commas, colons, dots)
    (lambda s: s.record("actions", {"v": 'x.y\\",\\"z:' * 1000, "w": ['p.q",', "r"], "n": {"ok": 1, "$set": 2}},
                        stored_type="x"), "actions.n: field name '$set'"),
    (lambda s: s.query("actions", filters={"$or": []}), "filter field '$or'"),
    (lambda s: s.query("actions", limit=0), "limit 0"),
    (lambda s: s.query("actions", since=datetime(2030, 1, 1, tzinfo=timezone.utc),
                       until=datetime(2020, 1, 1, tzinfo=timezone.utc)), "since"),
])
def test_bad_input_is_a_clear_error(store: InformationState, call, message: str) -> None:
    with pytest.raises(StoreError, match=message.replace("$", r"\$").replace(".", r"\.")):
        call(store)


def test_values_that_look_like_bad_keys_are_stored_as_they_are(store: InformationState) -> None:
    """Only keys are refused: a value holding '"a.b":' or '{"$x":' is text like any other."""
    doc = {"id": "v1", "text": '{"$where": 1, "a.b": 2},"c.d":', "list": ['",".":', "$x"]}
    store.record("actions", doc, stored_type="x")
    assert store.flush()
    stored = store.query("actions", filters={"id": "v1"})[0]
    assert {k: stored[k] for k in doc} == doc


def test_nan_is_stored_as_null_not_lost(store: InformationState) -> None:
    store.record("sensor_messages", {"id": "e1", "distance": math.nan}, stored_type="printeps/Entrance")
    assert store.flush()
    assert store.query("sensor_messages", filters={"id": "e1"})[0]["distance"] is None


@pytest.fixture
def both_stores(mongo, tmp_path, request: pytest.FixtureRequest):
    """A store shipping from a thread and one shipping from its shipper process, on databases of
    their own: an outage test puts both through the same outage (one wait, both ways checked)."""
    name = request.node.name[:40]
    stores = [InformationState(mongo.uri, f"t_{way[0]}_{name}", tmp_path / way / "journal", backend="embedded",
                               timeout_ms=500, retry_interval_s=0.2, ship_process=way == "process")
              for way in ("thread", "process")]
    yield stores
    for store in stores:
        store.close()


def _outage_under_load(stores: list[InformationState], mongo, outage_s: float) -> None:
    """Write continuously to each store while the DB is down for ``outage_s``; every document must
    arrive once. One outage for all the stores: the wait is the test's cost, not each store's."""
    written: list[list[str]] = [[] for _ in stores]
    stop = threading.Event()

    def writer(store: InformationState, out: list[str]) -> None:
        i = 0
        while not stop.is_set():
            out.append(store.record("sensor_messages", {"seq": i}, stored_type="printeps/Entrance"))
            i += 1
            time.sleep(0.005)

    threads = [threading.Thread(target=writer, args=(store, out)) for store, out in zip(stores, written)]
    for th in threads:
        th.start()
    try:
        assert wait_for(lambda: all(len(out) >= 20 for out in written), 10)  # writing before the outage
        mongo.stop()
        assert wait_for(lambda: all(store.health()["status"] == "degraded" for store in stores), 10)
        time.sleep(outage_s)  # the outage itself is what is tested: its length is the point, not a wait for a condition
        assert all(store.health()["buffered"] > 0 for store in stores)
        mongo.start()
        counts = [len(out) for out in written]
        assert wait_for(lambda: all(len(out) >= n + 20 for out, n in zip(written, counts)), 10)  # and after it
    finally:
        stop.set()
        for th in threads:
            th.join(timeout=10)
    for store, out in zip(stores, written):
        assert wait_for(lambda: store.health()["status"] == "ok", 30), store.health()
        assert store.flush(30), store.health()
        assert store.count("sensor_messages") == len(out)
        assert sorted(d["seq"] for d in store.query("sensor_messages", limit=1000, newest_first=False)
                      )[: min(1000, len(out))] == list(range(min(1000, len(out))))


def test_db_outage_under_load_loses_nothing(both_stores: list[InformationState], mongo) -> None:
    _outage_under_load(both_stores, mongo, outage_s=3.0)


@pytest.mark.slow
def test_db_outage_30s_under_load_loses_nothing(both_stores: list[InformationState], mongo) -> None:
    _outage_under_load(both_stores, mongo, outage_s=30.0)


def test_a_store_client_waits_long_enough_to_see_the_database_back() -> None:
    """A driver checks a server it last saw down at most every ``minHeartbeatFrequencyMS`` (500 ms
    by MongoDB's server discovery specification): with a server selection shorter than two of those,
    the first read after an outage could end before the check that finds the database back. The 30 s
    outage test failed so once, with ``timeout_ms`` 500: "Connection refused" from a database up and
    holding every document."""
    from gateway.store.shipper import mongo_client

    for timeout_ms in (100, 500, 1000, 5000):
        client = mongo_client("mongodb://127.0.0.1:9/?directConnection=true", timeout_ms)
        try:
            selection = client.options.server_selection_timeout
            assert selection >= 2 * 0.5 and selection >= timeout_ms / 1000
            assert client.options.pool_options.connect_timeout == timeout_ms / 1000  # the rest as configured
        finally:
            client.close()


def _journalled(folder) -> int:
    return sum(len([x for x in p.read_text().splitlines() if x.strip()]) for p in folder.glob("*.jsonl"))


def test_journal_survives_a_gateway_restart(mongo, tmp_path) -> None:
    journal = tmp_path / "journal"
    s1 = InformationState(mongo.uri, "t_restart", journal, timeout_ms=300, retry_interval_s=0.2)
    s1.record("actions", {"n": 1}, stored_type="printeps/Action")
    assert s1.flush()
    mongo.stop()
    s1.record("actions", {"n": 2}, stored_type="printeps/Action")
    s1.record("actions", {"n": 3}, stored_type="printeps/Action")
    s1.close(flush_timeout_s=1)
    assert _journalled(journal) == 2  # kept on disk, not lost
    mongo.start()
    s2 = InformationState(mongo.uri, "t_restart", journal, timeout_ms=300, retry_interval_s=0.2)
    try:
        assert wait_for(lambda: s2.health()["status"] == "ok" and s2.health()["buffered"] == 0, 20), s2.health()
        assert sorted(d["n"] for d in s2.query("actions")) == [1, 2, 3]
        assert _journalled(journal) == 0
    finally:
        s2.close()


KILLED_WRITER = """
import os, sys, time
from gateway.store.store import InformationState
s = InformationState("mongodb://127.0.0.1:1/?directConnection=true", "t_killed", sys.argv[1], timeout_ms=200,
                     retry_interval_s=60)
ids = [s.record("decisions", {"n": i}, stored_type="printeps/Decision") for i in range(5)]
print(" ".join(ids), flush=True)
time.sleep(600)
"""


def test_writes_of_a_killed_process_are_adopted_and_shipped(mongo, tmp_path) -> None:
    """A write acknowledged by record() survives SIGKILL of its process: another process (here a
    store over the same data dir) adopts the journal left behind and ships it, exactly once."""
    import signal
    import subprocess
    import sys

    journal = tmp_path / "journal"
    proc = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(journal)], stdout=subprocess.PIPE, text=True)
    try:
        ids = proc.stdout.readline().split()
        assert len(ids) == 5
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
    assert _journalled(journal) == 5
    survivor = InformationState(mongo.uri, "t_killed", journal, timeout_ms=500, retry_interval_s=0.2)
    try:
        assert wait_for(lambda: survivor.count("decisions") == 5, 20)
        assert sorted(str(d["_id"]) for d in survivor.query("decisions")) == sorted(ids)
        assert wait_for(lambda: _journalled(journal) == 0, 10)
    finally:
        survivor.close()


def test_full_spool_refuses_and_reports(mongo, tmp_path) -> None:
    s = InformationState("mongodb://127.0.0.1:1/?directConnection=true", "t_full", tmp_path / "sp.jsonl",
                         timeout_ms=200, spool_max_docs=2, retry_interval_s=5)
    try:
        for i in range(4):
            s.record("actions", {"n": i}, stored_type="printeps/Action")
        assert wait_for(lambda: s.health()["last_error"], 10)
        h = s.health()
        assert h["status"] == "degraded" and h["buffered"] == 2 and h["dropped"] == 2
        assert h["last_error"]
    finally:
        s.close(flush_timeout_s=0.5)


def test_open_store_starts_the_embedded_db_and_stops_it(settings, monkeypatch) -> None:
    monkeypatch.delenv("MONGO_URI", raising=False)
    store = open_store(settings)
    try:
        assert store.health()["backend"] == "embedded"
        store.record("actions", {"a": 1}, stored_type="printeps/Action")
        assert store.flush()
        assert store.count("actions") == 1
        proc = store.embedded.proc
    finally:
        store.close()
    assert proc.poll() is not None


def test_an_embedded_db_on_a_port_another_database_serves_refuses_to_start(mongo, tmp_path) -> None:
    """A restart after an outage, or a configured ``store.embedded_port``, may find the port taken by
    another database: that one answered the start's ping, the start returned, this daemon exited
    for want of the port, and the gateway wrote to the other database. Now the start fails naming
    the process that serves the port, and the other database goes on serving."""
    from gateway.store.embedded import EmbeddedDbError, EmbeddedMongo

    second = EmbeddedMongo(tmp_path / "second", port=mongo.port)
    with pytest.raises(EmbeddedDbError, match=rf"127.0.0.1:{mongo.port} is already served by another database "
                                              rf"process \(pid {mongo.proc.pid}\).*store.embedded_port"):
        second.start(timeout_s=20)
    assert second.proc is None  # its own daemon was stopped
    with pymongo.MongoClient(mongo.uri, serverSelectionTimeoutMS=2000) as client:
        assert client.admin.command("ping")["ok"] == 1


def test_the_embedded_db_keeps_its_replication_log_to_the_configured_bound(settings, monkeypatch) -> None:
    """Each decision writes about two replication-log entries; the daemon's own default keeps 100,000
    (about 80 minutes of a busy gateway) in memory. The launcher passes the gateway's bound; the daemon
    prunes to it every 1,000 writes."""
    monkeypatch.delenv("MONGO_URI", raising=False)
    settings.store.embedded_oplog_max_entries = 100
    store = open_store(settings)
    try:
        for i in range(2500):
            store.record("actions", {"a": i}, stored_type="printeps/Action")
        assert store.flush()
        assert store.count("actions") == 2500
        client = pymongo.MongoClient(store.embedded.uri)
        try:
            kept = client.local["oplog.rs"].count_documents({})
            assert kept <= 100 + 1000, kept  # 2,500+ without the bound
        finally:
            client.close()
    finally:
        store.close()


def test_mongo_uri_selects_an_external_db(settings, mongo, monkeypatch) -> None:
    monkeypatch.setenv("MONGO_URI", mongo.uri)
    store = open_store(settings)
    try:
        assert store.health()["backend"] == "external" and store.embedded is None
        assert store.health()["status"] == "ok"
    finally:
        store.close()


def test_a_document_the_database_refuses_is_set_aside_and_holds_up_nothing(store: InformationState) -> None:
    huge = {"blob": "x" * (17 * 1024 * 1024)}  # over MongoDB's 16 MB document limit
    store.record("actions", {"n": 1}, stored_type="printeps/Action")
    store.record("actions", huge, stored_type="printeps/Action")
    store.record("actions", {"n": 2}, stored_type="printeps/Action")
    assert store.flush(30)
    assert sorted(d["n"] for d in store.query("actions")) == [1, 2]
    assert store.health()["set_aside"] == 1
    refused = (store.journal.folder / "refused.jsonl").read_text()
    assert "DocumentTooLarge" in refused or "too large" in refused.lower()


def test_decisions_keep_two_secondary_indexes_and_retire_the_old_ones(store: InformationState) -> None:
    """Every index is a write per recorded fire: decisions keep (ruleset, _id) and (correlation_id,
    _id) only; indexes an earlier version made are dropped at start, and filters still answer
    without them."""
    from gateway.engine.recorder import DecisionRecorder
    from gateway.engine.results import FireResult
    from gateway.store.decisions import DecisionRecord

    coll = store.db["decisions"]
    coll.create_index([("origin", 1), ("_id", -1)])
    coll.create_index([("fired", 1), ("_id", -1)])
    record = DecisionRecord(store)
    recorder = DecisionRecorder(lambda kind, payload: None)
    recorder.journal_to(record)
    for i in range(3):
        recorder.record(FireResult(f"r{i % 2}", 1, [], [{"rule": f"rule {i}"}]), [], origin="rest" if i else "kie")
    assert store.flush(10)
    assert sorted(coll.index_information()) == ["_id_", "correlation_id_1__id_1", "ruleset_1__id_-1"]
    assert [d["ruleset"] for d in record.find(origin="rest")[0]] == ["r0", "r1"]
    assert [d["origin"] for d in record.find(rule="rule 0")[0]] == ["kie"]
    assert len(record.find(ruleset="r0")[0]) == 2


def test_a_trace_reads_its_decisions_through_the_correlation_index(store: InformationState) -> None:
    """The decisions of one correlation id are found by the index, not by scanning: the server's
    own plan (SecantusDB answers ``explain`` with the plan and what it examined) reads the index
    and examines only the matching documents, however many others are recorded."""
    from gateway.engine.recorder import DecisionRecorder
    from gateway.engine.results import FireResult
    from gateway.store.decisions import CORRELATION_INDEX, DecisionRecord

    record = DecisionRecord(store)
    recorder = DecisionRecorder(lambda kind, payload: None)
    recorder.journal_to(record)
    for i in range(300):
        recorder.record(FireResult("r", 1, [], []), [], origin="rest", correlation_id=f"req-{i % 30}" if i % 3 else None)
    assert store.flush(10)
    keys = {name: info["key"] for name, info in store.db["decisions"].index_information().items()}
    assert list(CORRELATION_INDEX) in [list(k) for k in keys.values()]
    expected = [i for i in range(300) if i % 3 and i % 30 == 7]
    assert len(record.by_correlation("req-7")) == len(expected) == 10
    plan = store.db["decisions"].find({"correlation_id": "req-7"}).sort("_id", 1).explain()
    stats = plan["executionStats"]
    assert stats["totalKeysExamined"] == stats["totalDocsExamined"] == len(expected), plan["queryPlanner"]
    assert "COLLSCAN" not in str(plan["queryPlanner"]["winningPlan"])


def test_a_decision_s_at_stamp_is_at_text_of_the_same_instant():
    """The recorder's cheap stamp (at_text_ns, the second's text kept between calls) writes what
    at_text writes for the same instant: milliseconds rounded up, a second's carry, any order."""
    import random
    from datetime import datetime, timedelta, timezone

    from gateway.store.decisions import at_text, at_text_ns, now_text

    epoch = datetime(1970, 1, 1, tzinfo=timezone.utc)
    base = 1_795_000_000 * 10**9
    edges = [0, 1, 999, 1_000, 1_001, 999_999, 1_000_000, 1_000_001, 999_000_000, 999_000_001, 999_999_999]
    instants = [base + e for e in edges] + [base + random.Random(7).randrange(10**12) for _ in range(2000)]
    random.Random(8).shuffle(instants)  # the kept second changes back and forth
    for ns in instants:
        assert at_text_ns(ns) == at_text(epoch + timedelta(microseconds=ns // 1000)), ns
    before = at_text(datetime.now(timezone.utc) - timedelta(milliseconds=1))
    stamp = now_text()
    assert before <= stamp <= at_text(datetime.now(timezone.utc))
