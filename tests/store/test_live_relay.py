"""The live relay: other processes' decisions, actions and detections reach this process's live
feed while someone watches it (real MongoDB-protocol server; change streams and polling)."""

from __future__ import annotations

import time

import pytest

from gateway.engine.recorder import DecisionRecorder
from gateway.engine.results import FireResult
from gateway.runtime.live import LiveFeed
from gateway.store.decisions import DecisionRecord
from gateway.store.live_relay import LiveRelay
from gateway.store.store import InformationState

WAIT_S = 15.0


def kinds_seen(subscription, want: int) -> list[dict]:
    events: list[dict] = []
    deadline = time.monotonic() + WAIT_S
    while len(events) < want and time.monotonic() < deadline:
        got, _dropped = subscription.take()
        events += got
        time.sleep(0.02)
    return events


def wait_until(cond) -> None:
    deadline = time.monotonic() + WAIT_S
    while not cond():
        assert time.monotonic() < deadline
        time.sleep(0.02)


@pytest.mark.parametrize("change_streams", [True, False], ids=["change-streams", "polling"])
def test_other_processes_writes_reach_a_watched_feed_and_its_own_do_not(store: InformationState,
                                                                       change_streams: bool) -> None:
    feed = LiveFeed()
    # this "process" is another one than the store's writer: it relays what the store writes
    relay = LiveRelay(store.db, feed, "another-host:1", change_streams=change_streams, poll_interval_s=0.1)
    own = LiveRelay(store.db, LiveFeed(), store.process, change_streams=change_streams, poll_interval_s=0.1)
    recorder = DecisionRecorder(lambda kind, payload: None)
    recorder.journal_to(DecisionRecord(store))

    def decide() -> str:
        return recorder.record(FireResult("reception", 2, [{"module": "say"}], [{"rule": "greet"}]), [], origin="ros")

    try:
        decide()
        assert store.flush(10)
        # nobody watches: nothing is followed (that decision is never relayed: see the first event below)
        assert not relay.following.is_set() and relay.relayed == 0
        watcher = feed.subscribe(replay=False)
        own.feed.subscribe(replay=False)
        wait_until(lambda: relay.following.is_set() and own.following.is_set())  # both noticed their subscriber
        decision_id = decide()
        store.record("actions", {"action": {"module": "say", "params": {"text": "hi"}}, "status": "ok",
                                 "decision_id": decision_id, "ruleset": "reception"},
                     stored_type="printeps/Action/ok", inserted_by="gateway")
        store.record("query_results", {"query": "entry", "window": 3, "rows": [{"p": "g1"}], "solutions": 1},
                     stored_type="printeps/QueryResult/entry", inserted_by="stream_engine")
        store.record("sensor_messages", {"source": "/entrance"}, stored_type="x", inserted_by="ros")  # not relayed
        assert store.flush(10)
        events = kinds_seen(watcher, 3)
        assert [e["kind"] for e in events] == ["decision", "action", "detection"]
        assert events[0]["decision_id"] == decision_id and events[0]["origin"] == "ros" and events[0]["fired"] == ["greet"]
        assert events[1]["decision_id"] == decision_id and events[1]["status"] == "ok"
        assert events[2]["query"] == "entry" and events[2]["rows"] == [{"p": "g1"}]
        assert own.relayed == 0  # a process never relays its own writes (its feed has them already)
    finally:
        relay.close()
        own.close()
