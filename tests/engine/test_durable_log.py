"""The plain-Python part of durable sessions (gateway.engine.durable): which batches are journalled,
when a snapshot may be taken, what an entry keeps, and the order a rebuild tries its starts in
and replays entries (over a recording stand-in for the Java session; the real one is exercised in
tests/api/test_durable_sessions.py and tests/cluster/test_durable_takeover.py)."""

from __future__ import annotations

import hashlib
import json
from typing import Any

import pytest

from gateway.engine import durable
from gateway.engine.durable import Durability, History, RebuildFailed, Snapshot


class MemoryLog:
    def __init__(self) -> None:
        self.entries: list[dict[str, Any]] = []
        self.snapshots: list[Snapshot] = []
        self.refuse = False
        self.shared = True
        self.waits: list[float] = []

    def append(self, ruleset: str, session_id: str, epoch: str, entry: dict[str, Any]) -> None:
        if self.refuse:
            raise RuntimeError("journal full")
        self.entries.append(entry)

    def save_snapshot(self, ruleset: str, session_id: str, epoch: str, snapshot: Snapshot) -> None:
        self.snapshots.insert(0, snapshot)

    def wait_shipped(self, timeout_s: float) -> bool:
        self.waits.append(timeout_s)
        return self.shared

    def has_room(self, writes: int = 1) -> bool:
        return not self.refuse


class Java:
    """Records what a rebuild does to a Java session; answers like the real one."""

    def __init__(self, version: int, journal: list[str], fail_restore: str | None = None) -> None:
        self.version, self.journal, self.fail_restore = version, journal, fail_restore
        self.disposed = False
        self.inserted = 0

    def restore(self, state: str) -> str:
        self.journal.append(f"v{self.version}.restore")
        return json.dumps({"ok": False, "message": self.fail_restore} if self.fail_restore else {"ok": True})

    def execute(self, commands: str, limit: int) -> str:
        self.journal.append(f"v{self.version}.execute {commands}")
        results = []
        for i, c in enumerate(json.loads(commands)):
            if c["op"] == "insert":
                results.append({"i": i, "op": "insert", "handles": [f"0:{self.inserted + k + 100}:9" for k in range(len(c["facts"]))]})
                self.inserted += len(c["facts"])
        return json.dumps({"ok": True, "results": results})

    def alias(self, held: str, now: str) -> str:
        self.journal.append(f"alias {held}->{now}")
        return '{"ok":true}'

    def currentHandle(self, text: str) -> str:  # noqa: N802 (the Java method's name)
        return text + "x"

    def moveFrom(self, old: "Java", unchanged: str) -> str:  # noqa: N802
        self.journal.append(f"v{self.version}.move from v{old.version} {unchanged}")
        return '{"ok":true}'

    def snapshot(self) -> str:
        return '{"ok":true,"time":5,"facts":[]}'

    def dispose(self) -> None:
        self.disposed = True


class Builder:
    def __init__(self, broken: set[int] | None = None, fail_restore: str | None = None) -> None:
        self.journal: list[str] = []
        self.broken = broken or set()
        self.fail_restore = fail_restore
        self.made: list[Java] = []

    def java_session(self, version: int) -> Java:
        if version in self.broken:
            raise RuntimeError(f"version {version} does not compile")
        java = Java(version, self.journal, self.fail_restore)
        self.made.append(java)
        return java

    def unchanged_rules(self, old: int, new: int) -> list[str]:
        return []


def _snap(seq: int, version: int = 1, state: str = '{"ok":true}') -> Snapshot:
    return Snapshot(seq, version, state, hashlib.sha256(state.encode()).hexdigest(), 1.0)


def _batch(seq: int, *commands: dict[str, Any], **extra: Any) -> dict[str, Any]:
    return {"kind": "batch", "seq": seq, "commands": list(commands), **extra}


def test_only_changing_batches_are_journalled():
    assert durable.changes([{"op": "insert", "facts": []}])
    assert durable.changes([{"op": "get_objects"}, {"op": "set_focus", "group": "g"}])
    assert not durable.changes([{"op": "get_objects"}, {"op": "query", "name": "q"}, {"op": "get_global", "name": "x"}])


@pytest.mark.parametrize("commands, fired, quiet", [
    ([{"op": "insert"}, {"op": "fire", "max": -1}], 3, True),
    ([{"op": "insert"}, {"op": "fire"}], 3, True),
    ([{"op": "insert"}, {"op": "fire", "max": -1}], 10, False),  # stopped by the runaway guard: matches may be left
    ([{"op": "insert"}, {"op": "fire", "max": 2}], 1, False),  # at most n: matches may be left
    ([{"op": "fire", "max": -1}, {"op": "insert"}], 1, False),  # inserted after the fire
    ([{"op": "fire", "max": -1}, {"op": "get_objects"}], 1, True),  # reads do not count
    ([{"op": "insert"}], 0, False),
])
def test_quiescent_tells_when_a_full_fire_left_nothing_to_fire(commands, fired, quiet):
    """(A snapshot is taken at any command; at these points, for rules without agenda groups, it only reads.)"""
    fire_index = next((i for i, c in enumerate(commands) if c["op"] == "fire"), None)
    results = [{"i": i, "op": c["op"], **({"fire": {"fireCount": fired}} if i == fire_index else {})}
               for i, c in enumerate(commands)]
    assert durable.quiescent(commands, results, fire_limit=10) is quiet


def test_an_entry_keeps_the_handles_inserts_returned_and_updates_left():
    commands = [{"op": "insert", "facts": [{"type": "T"}]}, {"op": "update", "handle": "0:1:5", "fact": {"type": "T"}},
                {"op": "modify", "handle": "0:2:6", "set": []}]
    results = [{"i": 0, "op": "insert", "handles": ["0:3:7"]}, {"i": 1, "op": "update"}, {"i": 2, "op": "modify"}]
    entry = durable.batch_entry(4, commands, results, 1000, lambda text: "0:1:8" if text == "0:1:5" else text)
    assert entry["seq"] == 4 and entry["time"] == 1000 and entry["commands"] == commands
    assert entry["handles"] == {"0": ["0:3:7"]} and entry["current"] == {"1": "0:1:8"}


def test_durability_counts_commands_and_snapshots_when_due():
    log = MemoryLog()
    state = Durability(log, "rs", "s1", "e1", every=2, interval_s=0)
    state.open({"version": 1})
    assert log.entries[0]["kind"] == "open" and log.entries[0]["seq"] == 0
    state.record([{"op": "insert", "facts": []}], [], 0, lambda t: t)
    assert not state.due() and state.commands_since_snapshot == 1
    state.record([{"op": "fire"}], [], 0, lambda t: t)
    assert state.due()
    assert state.snapshot(Java(3, []), 3)
    assert log.snapshots[0].seq == 2 and log.snapshots[0].version == 3 and log.snapshots[0].readable()
    assert state.info() == {"durable": True, "last_snapshot": log.snapshots[0].at, "commands_since_snapshot": 0}
    log.refuse = True
    with pytest.raises(RuntimeError):
        state.record([{"op": "fire"}], [], 0, lambda t: t)
    assert state.seq == 2  # a refused entry takes no number


def test_a_changing_batch_is_refused_before_it_runs_when_the_journal_is_full():
    log = MemoryLog()
    state = Durability(log, "rs", "s1", "e1", every=10, interval_s=0)
    state.check_room([{"op": "insert", "facts": []}])
    log.refuse = True
    state.check_room([{"op": "get_objects"}])  # reads need no room
    with pytest.raises(durable.JournalRefused) as refused:
        state.check_room([{"op": "insert", "facts": []}])
    assert "journal is full" in str(refused.value) and refused.value.retry_after_s >= 1


def test_rebuild_restores_the_newest_snapshot_and_replays_what_follows_with_aliases():
    history = History({"version": 1}, [_snap(2)], [
        _batch(1, {"op": "insert", "facts": [{}]}),
        _batch(2, {"op": "fire"}),
        _batch(3, {"op": "insert", "facts": [{}, {}]}, handles={"0": ["0:7:1", "0:8:1"]}),
        {"kind": "move", "seq": 4, "from": 1, "to": 2, "unchanged": ["R"]},
        _batch(5, {"op": "update", "handle": "0:7:1", "fact": {}}, current={"0": "0:7:2"}),
    ])
    builder = Builder()
    rebuilt = durable.rebuild(history, builder, 10, "rs", "s1")
    assert builder.journal == [
        "v1.restore",
        'v1.execute [{"op":"insert","facts":[{},{}]}]', "alias 0:7:1->0:100:9", "alias 0:8:1->0:101:9",
        'v2.move from v1 ["R"]',
        'v2.execute [{"op":"update","handle":"0:7:1","fact":{}}]', "alias 0:7:2->0:7:1x"]
    assert rebuilt.version == 2 and rebuilt.seq == 5 and rebuilt.snapshot_seq == 2
    assert builder.made[0].disposed and not builder.made[1].disposed


def test_rebuild_falls_back_from_a_corrupt_snapshot_to_the_previous_then_to_the_log():
    corrupt = Snapshot(3, 1, '{"ok":true}', "0" * 64, 1.0)
    history = History({"version": 1}, [corrupt, _snap(1)], [_batch(1, {"op": "fire"}), _batch(2, {"op": "fire"}),
                                                             _batch(3, {"op": "fire"})])
    builder = Builder()
    rebuilt = durable.rebuild(history, builder, 10, "rs", "s1")
    assert rebuilt.snapshot_seq == 1 and rebuilt.seq == 3
    assert builder.journal[0] == "v1.restore" and len(builder.journal) == 3  # two replayed after snapshot 1
    builder = Builder(fail_restore="snapshot fact 0: the version declares no type T")
    rebuilt = durable.rebuild(history, builder, 10, "rs", "s1")
    assert rebuilt.snapshot_seq == 0 and builder.made[0].disposed  # both snapshots refused: the whole log


def test_rebuild_fails_whole_naming_the_session_and_every_reason():
    history = History({"version": 1}, [_snap(2, version=2)], [_batch(2, {"op": "fire"}), _batch(3, {"op": "fire"})])
    with pytest.raises(RebuildFailed) as failed:
        durable.rebuild(history, Builder(broken={2}), 10, "rs", "s1")
    assert "session s1 of rs" in str(failed.value) and "version 2 does not load" in str(failed.value)
    assert failed.value.status == 409
    assert not history.complete()
    corrupt = History({"version": 1}, [Snapshot(2, 1, "{", "bad", 1.0)], [_batch(3, {"op": "fire"})])
    with pytest.raises(RebuildFailed) as failed:
        durable.rebuild(corrupt, Builder(), 10, "rs", "s1")
    assert failed.value.status == 422 and "corrupt" in str(failed.value)


def test_ack_after_database_waits_for_the_entry_to_be_shared_and_says_when_it_is_not():
    log = MemoryLog()
    local = Durability(log, "rs", "s1", "e1", every=10, interval_s=0)
    local.record([{"op": "fire"}], [], 0, lambda t: t)
    assert log.waits == []  # ack_after: journal: no wait
    shared = Durability(log, "rs", "s2", "e2", every=10, interval_s=0, shared_within_s=3.0)
    shared.record([{"op": "fire"}], [], 0, lambda t: t)
    assert log.waits == [3.0]
    log.shared = False
    with pytest.raises(durable.NotYetShared, match="do not resend"):
        shared.record([{"op": "fire"}], [], 0, lambda t: t)
    assert shared.seq == 2 and len(log.entries) == 3  # journalled (kept), only not yet shared
