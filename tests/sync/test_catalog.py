"""The catalog of versions in a real MongoDB-protocol server and the change follower: two
"processes" (two catalogs over one database) see each other's changes; a bad log entry or a gap
never stops a follower."""

from __future__ import annotations

import logging
import time

import pytest

from gateway.runtime.follower import ChangeFollower
from gateway.store.catalog import CHANGES, MongoCatalog
from gateway.base.versions import CatalogConflict, MemoryCatalog, VersionMissing


class Recorder:
    """A followed service that only notes what it was asked to converge."""

    def __init__(self) -> None:
        self.synced: list[str] = []
        self.reconciled = 0

    def sync(self, name: str) -> None:
        if name == "explodes":
            raise RuntimeError("cannot apply")
        self.synced.append(name)

    def reconcile(self) -> None:
        self.reconciled += 1


def wait_for(cond, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.02)
    return bool(cond())


@pytest.fixture(params=["mongo", "memory"])
def catalogs(request, store):
    """Two catalogs over the same source of truth (two processes), on MongoDB or in memory."""
    if request.param == "memory":
        first = MemoryCatalog("p1")
        return first, first.sharing("p2")
    return MongoCatalog(store.db, "p1"), MongoCatalog(store.db, "p2")


def test_versions_heads_conflicts_rollback_delete_history(catalogs):
    one, two = catalogs
    assert one is not two and (one.origin, two.origin) == ("p1", "p2")
    info, seq1 = one.save("ruleset", "r", {"files": {"a.drl": "x"}}, author="alice", comment="first", hash="h1",
                          base_version=0)
    assert info.version == 1 and two.head("ruleset", "r").current == 1
    with pytest.raises(CatalogConflict) as stale:
        two.save("ruleset", "r", {"files": {}}, author="bob", comment="", hash="h", base_version=0)
    assert stale.value.current == 1
    info2, seq2 = two.save("ruleset", "r", {"files": {"a.drl": "y"}}, author="bob", comment="second", hash="h2",
                           base_version=1)
    assert info2.version == 2 and seq2 > seq1
    assert one.load("ruleset", "r", 1).payload == {"files": {"a.drl": "x"}}
    back, _ = one.set_current("ruleset", "r", 1, author="alice", comment="undo")
    assert back.version == 1 and two.head("ruleset", "r").current == 1
    two.delete("ruleset", "r", author="bob")
    head = one.head("ruleset", "r")
    assert head.deleted and not head.live and head.last == 2
    with pytest.raises(VersionMissing):
        one.delete("ruleset", "r", author="alice")
    info3, _ = one.save("ruleset", "r", {"files": {}}, author="alice", comment="again", hash="h3")
    assert info3.version == 3  # numbering continues after a delete
    assert [c.event for c in two.history("ruleset", "r")] == ["deploy", "deploy", "rollback", "delete", "deploy"]
    # each change names the process that made it, seen alike from both
    assert [c.origin for c in one.history("ruleset", "r")] == ["p1", "p2", "p1", "p2", "p1"]
    assert [v.version for v in two.versions("ruleset", "r")] == [1, 2, 3]
    assert one.changes_since(0)[-1].seq == two.last_seq()



def test_the_log_keeps_who_in_which_role_from_which_process_and_refusals(catalogs):
    """The audit (issue 26): every deploy, rollback and delete with its principal, role and process;
    a policy refusal is logged too, moves nothing, and a follower does not act on it."""
    one, two = catalogs
    one.save("ruleset", "audited", {"a.drl": "x"}, author="dora", comment="", hash="h1", role="developer")
    seq = two.refuse("ruleset", "audited", author="alice", role="author", comment="r.drl:3:5: rule policy: …")
    assert seq == one.last_seq() and one.head("ruleset", "audited").current == 1
    one.set_current("ruleset", "audited", 1, author="dora", comment="", role="developer")
    two.delete("ruleset", "audited", author="alice", role="author")
    log = [(c.event, c.author, c.role, c.origin) for c in one.history("ruleset", "audited")]
    p2 = "p1" if one is two else "p2"
    assert log == [("deploy", "dora", "developer", "p1"), ("refused", "alice", "author", p2),
                   ("rollback", "dora", "developer", "p1"), ("delete", "alice", "author", p2)]
    recorder = Recorder()
    follower = ChangeFollower(one, {"ruleset": recorder}, start_seq=0)
    follower.poll()
    assert recorder.synced.count("audited") == 3  # not for the refusal

def test_concurrent_saves_never_share_a_version(store):
    import threading

    catalogs = [MongoCatalog(store.db, f"p{i}") for i in range(4)]
    got: list[int] = []

    def deploy(catalog: MongoCatalog) -> None:
        for _ in range(5):
            got.append(catalog.save("workflow", "w", {"text": "x"}, author="a", comment="", hash="h")[0].version)

    threads = [threading.Thread(target=deploy, args=(c,)) for c in catalogs]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(got) == list(range(1, 21))
    assert catalogs[0].head("workflow", "w").last == 20


def test_follower_applies_every_change_of_another_process(store):
    writer, reader = MongoCatalog(store.db, "writer"), MongoCatalog(store.db, "reader")
    seen = Recorder()
    follower = ChangeFollower(reader, {"ruleset": seen}, start_seq=reader.last_seq()).start()
    try:
        writer.save("ruleset", "a", {}, author="x", comment="", hash="1")
        writer.save("ruleset", "b", {}, author="x", comment="", hash="2")
        writer.delete("ruleset", "a", author="x")
        assert wait_for(lambda: seen.synced == ["a", "b", "a"]), seen.synced
    finally:
        follower.stop()


def test_a_malformed_change_entry_is_skipped_with_a_reason_and_following_goes_on(store, caplog):
    writer, reader = MongoCatalog(store.db, "writer"), MongoCatalog(store.db, "reader")
    seen = Recorder()
    follower = ChangeFollower(reader, {"ruleset": seen}, start_seq=reader.last_seq()).start()
    try:
        caplog.set_level(logging.ERROR)
        bad_seq = writer._next_seq()
        store.db[CHANGES].insert_one({"_id": bad_seq, "seq": bad_seq, "kind": "ruleset"})  # no name, no event
        unknown = writer._next_seq()
        store.db[CHANGES].insert_one({"_id": unknown, "seq": unknown, "kind": "spaceship", "name": "x",
                                      "event": "deploy"})
        writer.save("ruleset", "explodes", {}, author="x", comment="", hash="1")  # its service fails to apply it
        writer.save("ruleset", "after", {}, author="x", comment="", hash="2")
        assert wait_for(lambda: "after" in seen.synced), seen.synced
        assert follower.errors >= 1 and follower.skipped >= 1 and follower.health()["status"] == "ok"
        assert f"skipped malformed change-log entry {bad_seq}" in caplog.text
        assert "unknown kind 'spaceship'" in caplog.text
    finally:
        follower.stop()


def test_a_gap_in_the_log_is_waited_for_then_passed_over(store):
    writer, reader = MongoCatalog(store.db, "writer"), MongoCatalog(store.db, "reader")
    seen = Recorder()
    follower = ChangeFollower(reader, {"ruleset": seen}, start_seq=reader.last_seq(), gap_wait_s=0.5)
    lost = writer._next_seq()  # a writer that died between claiming a number and logging it
    writer.save("ruleset", "later", {}, author="x", comment="", hash="1")
    follower.poll()
    assert seen.synced == ["later"]  # entries past the gap are applied at once
    assert follower.low_water == lost - 1
    time.sleep(0.6)
    follower.poll()
    assert follower.low_water > lost  # the gap is passed over


def test_reconcile_asks_every_service(store):
    seen = Recorder()
    follower = ChangeFollower(MongoCatalog(store.db, "r"), {"ruleset": seen, "workflow": seen}, start_seq=0)
    follower.reconcile()
    assert seen.reconciled == 2


def test_a_version_left_by_a_dead_writer_does_not_block_the_next_deploy(store):
    from gateway.store.catalog import VERSIONS

    catalog = MongoCatalog(store.db, "p")
    catalog.save("ruleset", "r", {}, author="a", comment="", hash="1")
    # a writer claimed version 2 and died before moving the head
    store.db[VERSIONS].insert_one({"_id": "ruleset/r/2", "kind": "ruleset", "name": "r", "version": 2,
                                   "deployed_at": "2026-01-01T00:00:00.000Z", "author": "dead", "comment": "", "hash": "x", "payload": "{}"})
    info, _ = catalog.save("ruleset", "r", {}, author="b", comment="", hash="3", base_version=1)
    assert info.version == 3 and catalog.head("ruleset", "r").current == 3
