"""The journal's hand-over between processes on one data dir, under races (unit tests: the
database is replaced by a file each process appends what it "ships" to; the journal's contract
with the database is tested against a real server in test_store.py)."""

from __future__ import annotations

import fcntl
import json
import os
import random
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from gw_testing import wait_for

import gateway.store.journal as journal_module
from gateway.store.journal import Journal, encode

ROOT = Path(__file__).resolve().parents[2]

# A writer process: journals numbered writes as fast as it can, writing each id to acked-<pid>
# once append() returned (what a fire's answer would acknowledge); shipping appends the ids to
# shipped-<pid>. Small segments and a 10 ms adoption interval make the races frequent.
WRITER = """
import json, os, random, sys, time
sys.path.insert(0, sys.argv[3])
import gateway.store.journal as J
J.SEGMENT_BYTES = 4096
folder, out = sys.argv[1], sys.argv[2]
pid = os.getpid()
shipped = os.open(f"{out}/shipped-{pid}", os.O_WRONLY | os.O_CREAT | os.O_APPEND)
acked = os.open(f"{out}/acked-{pid}", os.O_WRONLY | os.O_CREAT | os.O_APPEND)
def ship(db, c, lines):
    time.sleep(random.random() * 0.003)
    os.write(shipped, "".join(json.loads(x)["d"]["id"] + "\\n" for x in lines).encode())
j = J.Journal(folder, ship, adopt_interval_s=0.01, batch=20)
n = 0
while True:
    n += 1
    i = f"{pid}-{n}"
    j.append("db", "c", [J.encode("db", "c", {"id": i, "pad": "x" * 100})])
    os.write(acked, (i + "\\n").encode())
    time.sleep(random.random() * 0.001)
"""


def ids_in(files: list[Path]) -> set[str]:
    return {line for f in files for line in f.read_text().split()}


def test_writers_killed_at_random_lose_no_acknowledged_write_and_no_shipper_dies(tmp_path: Path) -> None:
    """Three processes write, and are SIGKILLed and restarted at random, while the others adopt
    what the dead left (the races: two adopters on one file, an adopter on a segment its writer
    is deleting or creating). Every acknowledged write is shipped, and no shipper thread dies."""
    folder, out = tmp_path / "journal", tmp_path / "out"
    folder.mkdir()
    out.mkdir()
    logs = [open(tmp_path / f"writer-{k}.log", "ab") for k in range(3)]

    def start(k: int) -> subprocess.Popen:
        return subprocess.Popen([sys.executable, "-c", WRITER, str(folder), str(out), str(ROOT)],
                                stdout=logs[k], stderr=subprocess.STDOUT)

    rng = random.Random(7)
    procs = [start(k) for k in range(3)]
    def acked_now() -> int:
        return len(ids_in(list(out.glob("acked-*"))))

    try:
        # at least 15 random kills and enough hand-overs to matter (> 200 writes), however slow the
        # machine; the deadline is only a safety limit
        kills, deadline = 0, time.monotonic() + 180
        while kills < 15 or acked_now() <= 200:
            assert time.monotonic() < deadline, f"{acked_now()} writes acknowledged after {kills} kills"
            time.sleep(rng.random() * 0.8)
            k = rng.randrange(3)
            procs[k].send_signal(signal.SIGKILL)
            procs[k].wait()
            procs[k] = start(k)
            kills += 1
        before = acked_now()
        assert wait_for(lambda: acked_now() >= before + 20, 60)  # the restarted writers write again
    finally:
        for p in procs:
            p.send_signal(signal.SIGKILL)
            p.wait()
        for log in logs:
            log.close()
    final = out / "final"

    def ship(db: str, c: str, lines: list[bytes]) -> None:
        with open(final, "a") as fh:
            fh.write("".join(json.loads(x)["d"]["id"] + "\n" for x in lines))

    last = Journal(folder, ship, adopt_interval_s=0.01)
    try:
        assert wait_for(lambda: not [*folder.glob("*.jsonl"), *folder.glob("*.jsonl.adopted")], 60), \
            "segments left unadopted"
        assert last.flush(10)
    finally:
        last.close()
    acked = ids_in(list(out.glob("acked-*")))
    shipped = ids_in(list(out.glob("shipped-*")) + ([final] if final.exists() else []))
    assert len(acked) > 200  # enough hand-overs to matter (ensured above)
    assert not acked - shipped, f"{len(acked - shipped)} acknowledged writes never shipped"
    output = "".join((tmp_path / f"writer-{k}.log").read_text(errors="replace") for k in range(3))
    assert "Traceback" not in output and "unexpectedly" not in output, output[-3000:]


def test_a_segment_deleted_between_open_and_lock_is_not_adopted(tmp_path: Path, monkeypatch) -> None:
    """Another adopter (or the segment's own writer, done shipping it) deletes the file after we
    opened it and before we locked it: it is skipped, not read again by name (which raised and
    killed the shipper thread)."""
    segment = tmp_path / "1-1-1.jsonl"
    segment.write_bytes(encode("db", "c", {"_id": "a"}))
    real_flock = fcntl.flock

    def flock_after_unlink(fd: int, op: int) -> None:
        if segment.exists():
            segment.unlink()
        real_flock(fd, op)

    monkeypatch.setattr(journal_module.fcntl, "flock", flock_after_unlink)
    assert journal_module._lock_orphan(segment) is None


def test_the_shipper_survives_an_unexpected_error_and_keeps_shipping(tmp_path: Path, monkeypatch, caplog) -> None:
    shipped: list[str] = []
    failures = iter([None, OSError("adoption broke")])  # the start's adoption passes, the shipper's breaks

    def adopt_once_broken(self: Journal) -> None:
        error = next(failures, None)
        if error is not None:
            raise error

    monkeypatch.setattr(Journal, "_adopt_orphans", adopt_once_broken)
    j = Journal(tmp_path, lambda db, c, lines: shipped.extend(json.loads(x)["d"]["_id"] for x in lines),
                adopt_interval_s=0.0, retry_interval_s=0.05)
    try:
        j.append("db", "c", [encode("db", "c", {"_id": str(n)}) for n in range(3)])
        assert j.flush(5)
        assert shipped == ["0", "1", "2"]
        assert j._thread.is_alive()
        assert "shipping failed unexpectedly" in caplog.text and "adoption broke" in caplog.text
    finally:
        j.close()


def test_unreadable_lines_of_an_adopted_segment_are_skipped_and_the_rest_shipped(tmp_path: Path, caplog) -> None:
    """A line that is not JSON, or not a {db, c, d: document} entry, is skipped with a warning: it
    must not hold up the good lines of the segment (as it would, retried forever, if shipped)."""
    (tmp_path / "1-1-1.jsonl").write_bytes(b"".join([
        encode("db", "c", {"_id": "a"}), b'{"db": "db", "c": "c", "d": 5}\n', b"{not json\n",
        b'{"db": 1, "c": "c", "d": {}}\n', encode("db", "c", {"_id": "b"}).rstrip(b"\n")]))
    shipped: list[str] = []
    j = Journal(tmp_path, lambda db, c, lines: shipped.extend(json.loads(x)["d"]["_id"] for x in lines))
    try:
        assert j.flush(5)
        assert shipped == ["a", "b"]
        assert caplog.text.count("skipped an unreadable line") == 3
        assert wait_for(lambda: not list(tmp_path.glob("*.jsonl")), 5)  # deleted just after it is shipped
    finally:
        j.close()


def test_what_the_database_refused_is_not_adopted_as_a_dead_writers_segment(tmp_path: Path) -> None:
    """refused.jsonl sits beside the segments, unlocked: it is kept as it is, never shipped again
    (it was: the document was refused and set aside a second time, and the file replaced)."""
    journal = Journal(tmp_path, lambda db, c, lines: None)
    journal.set_aside("db", "c", {"_id": "too-big"}, "DocumentTooLarge")
    kept = (tmp_path / "refused.jsonl").read_bytes()
    (tmp_path / "7-1-1.jsonl").write_bytes(encode("db", "c", {"_id": "orphan"}))  # a dead writer's segment
    shipped: list[str] = []
    other = Journal(tmp_path, lambda db, c, lines: shipped.extend(json.loads(x)["d"]["_id"] for x in lines),
                    adopt_interval_s=0.01)
    try:
        assert other.catch_up(5)  # adopts every unlocked segment there is, and ships it
        assert shipped == ["orphan"]
        assert (tmp_path / "refused.jsonl").read_bytes() == kept and journal.set_aside_count == 1
    finally:
        other.close()
        journal.close()


def test_a_new_segment_is_locked_before_adopters_can_see_it(tmp_path: Path, monkeypatch) -> None:
    """A segment is created and locked under ``*.jsonl.new`` and only then renamed: at no moment
    is an unlocked ``*.jsonl`` of a live writer there for an adopter to take."""
    seen: list[list[str]] = []
    real_flock = fcntl.flock

    def watching_flock(fd: int, op: int) -> None:
        seen.append(sorted(p.name for p in tmp_path.glob("*.jsonl")))
        real_flock(fd, op)

    j = Journal(tmp_path, lambda db, c, lines: None)
    try:
        monkeypatch.setattr(journal_module.fcntl, "flock", watching_flock)
        j.append("db", "c", [encode("db", "c", {"_id": "x"})])
        monkeypatch.undo()
        assert seen == [[]]
        assert [p.name.endswith(".jsonl") for p in tmp_path.glob("*.jsonl*")] == [True]
    finally:
        j.close()


def test_a_stale_new_file_is_removed_and_a_young_one_kept(tmp_path: Path) -> None:
    stale, young = tmp_path / "1-1-1.jsonl.new", tmp_path / "2-2-2.jsonl.new"
    stale.write_bytes(b"")
    young.write_bytes(b"")
    old = time.time() - journal_module.STALE_NEW_S - 5
    os.utime(stale, (old, old))
    j = Journal(tmp_path, lambda db, c, lines: None)
    try:
        assert not stale.exists() and young.exists()
    finally:
        j.close()


def test_failed_tries_back_off_with_smaller_batches_that_grow_back(tmp_path: Path) -> None:
    """A database that times out is retried later and later, in halved batches; once tries succeed
    the batches grow back to full size. Nothing is lost or shipped out of order."""
    calls: list[tuple[float, int]] = []
    shipped: list[int] = []
    failing = {"n": 3}

    def ship(db: str, c: str, lines: list[bytes]) -> None:
        calls.append((time.monotonic(), len(lines)))
        if failing["n"] > 0:
            failing["n"] -= 1
            raise TimeoutError("overloaded")
        shipped.extend(json.loads(x)["d"]["i"] for x in lines)

    j = Journal(tmp_path, ship, retry_interval_s=0.1, batch=80)
    try:
        j.append("db", "c", [encode("db", "c", {"i": i}) for i in range(400)])
        assert j.flush(10)
    finally:
        j.close()
    assert shipped == list(range(400))
    sizes = [n for _, n in calls]
    assert sizes[:5] == [80, 40, 20, 10, 20]  # halved on each failure, doubled back on success
    assert max(sizes[5:]) == 80
    waits = [b[0] - a[0] for a, b in zip(calls, calls[1:4])]
    assert waits[0] >= 0.1 and waits[1] >= 0.2 and waits[2] >= 0.4  # the backoff doubles


def test_a_batch_is_bounded_in_bytes(tmp_path: Path) -> None:
    """This process's writes and those adopted from a dead process alike."""
    left = tmp_path / "1-1-1.jsonl"  # a segment whose writer is gone
    left.write_bytes(b"".join(encode("db", "c", {"dead": k, "pad": "y" * 1000}) for k in range(30)))
    batches: list[int] = []
    j = Journal(tmp_path, lambda db, c, lines: batches.append(sum(map(len, lines))), batch=500,
                batch_bytes=10_000, linger_s=0.5)
    try:
        j.append("db", "c", [encode("db", "c", {"pad": "x" * 1000}) for _ in range(50)])
        assert j.flush(10)
    finally:
        j.close()
    assert sum(batches) > 80_000 and max(batches) <= 10_000
    assert not left.exists()


def test_closing_during_a_backoff_does_not_wait_it_out(tmp_path: Path) -> None:
    def down(db: str, c: str, lines: list[bytes]) -> None:
        raise ConnectionError("away")

    j = Journal(tmp_path, down, retry_interval_s=30)
    j.append("db", "c", [encode("db", "c", {"i": 1})])
    assert wait_for(lambda: j.degraded, 5)
    start = time.monotonic()
    j.close(timeout_s=10)
    assert time.monotonic() - start < 5
    assert list(tmp_path.glob("*.jsonl"))  # the write stays on disk for the next process


def test_catch_up_ships_a_dead_writers_segments_now_and_waits_for_another_adopter(tmp_path: Path) -> None:
    """What a durable session's rebuild relies on: every entry a dead process acknowledged is in
    the database when catch_up returns (adopted now, not at the next periodic look), and a dead
    process's segment another process is adopting at that moment is waited for."""
    shipped: list[str] = []
    dead_pid = 999_999_999
    (tmp_path / f"{dead_pid}-1-1.jsonl").write_bytes(b"".join(encode("db", "c", {"id": f"d{k}"}) for k in range(5)))
    journal = Journal(tmp_path, lambda db, c, lines: shipped.extend(json.loads(x)["d"]["id"] for x in lines),
                      adopt_interval_s=3600)
    try:
        journal.append("db", "c", [encode("db", "c", {"id": "mine"})])
        assert journal.catch_up(10, (dead_pid,))
        assert sorted(shipped) == ["d0", "d1", "d2", "d3", "d4", "mine"]
        assert not list(tmp_path.glob(f"{dead_pid}-*.jsonl"))
        # another adopter holds the next dead segment: catch_up waits for it to be gone
        other = tmp_path / f"{dead_pid}-1-2.jsonl"
        other.write_bytes(encode("db", "c", {"id": "theirs"}))
        fd = os.open(other, os.O_RDONLY)
        fcntl.flock(fd, fcntl.LOCK_EX)
        try:
            assert not journal.catch_up(0.3, (dead_pid,))
        finally:
            os.unlink(other)  # the other adopter shipped and deleted it
            os.close(fd)
        assert journal.catch_up(5, (dead_pid,))
    finally:
        journal.close()


def test_flush_and_catch_up_wait_for_the_adopted_writes_still_being_shipped(tmp_path: Path) -> None:
    """Issue 28: a dead owner's last acknowledged entry went missing from a durable session
    rebuilt elsewhere. The shipper had taken the adopted chunk holding it off the queue and was
    still shipping it, and neither flush nor catch_up counted it: they returned, the rebuild
    read the database without it. Both must wait until the chunk is in."""
    dead_pid = 999_999_999
    (tmp_path / f"{dead_pid}-1-1.jsonl").write_bytes(b"".join(encode("db", "c", {"id": f"d{k}"}) for k in range(3)))
    shipping, release = threading.Event(), threading.Event()
    shipped: list[str] = []

    def ship(db: str, c: str, lines: list[bytes]) -> None:
        shipping.set()
        assert release.wait(10)
        shipped.extend(json.loads(x)["d"]["id"] for x in lines)

    journal = Journal(tmp_path, ship, adopt_interval_s=3600)  # adopts the dead writer's segment as it starts
    try:
        assert shipping.wait(5)  # the adopted chunk is in the shipper's hands, not in the database
        assert not journal.flush(0.3)
        assert not journal.catch_up(0.3)  # no gone pid named: the rebuild after a forward found its owner gone
        assert shipped == []
        release.set()
        assert journal.catch_up(5)
        assert shipped == ["d0", "d1", "d2"]
        assert wait_for(lambda: not list(tmp_path.glob(f"{dead_pid}-*.jsonl")), 5)  # deleted once shipped
    finally:
        release.set()
        journal.close()


def test_catch_up_waits_for_a_dead_writers_segment_another_process_is_shipping_unnamed(tmp_path: Path) -> None:
    """Issue 28, with three processes on one host: the owner of a session dies, a third process
    adopts its segment and is still shipping it when the taker rebuilds through a failed forward,
    which knows no dead pid. The taker cannot lock that segment, so it used to think it had caught
    up and rebuilt without the dead owner's last entries. An adopter renames what it ships
    ``*.jsonl.adopted``, and catch_up waits until that is gone."""
    dead_pid = 999_999_999
    (tmp_path / f"{dead_pid}-1-1.jsonl").write_bytes(b"".join(encode("db", "c", {"id": f"d{k}"}) for k in range(3)))
    shipping, release = threading.Event(), threading.Event()
    shipped: list[str] = []

    def slow_ship(db: str, c: str, lines: list[bytes]) -> None:  # the third process's shipping, held up
        shipping.set()
        assert release.wait(10)
        shipped.extend(json.loads(x)["d"]["id"] for x in lines)

    third = Journal(tmp_path, slow_ship, adopt_interval_s=3600)  # adopts the dead writer's segment as it starts
    taker = Journal(tmp_path, lambda db, c, lines: None, adopt_interval_s=3600)
    try:
        assert shipping.wait(5)
        assert not taker.catch_up(0.3)  # no gone pid named, and the segment is not the taker's to ship
        assert [p.name for p in tmp_path.glob("*.jsonl*")] == [f"{dead_pid}-1-1.jsonl.adopted"]
        release.set()
        assert taker.catch_up(5)
        assert shipped == ["d0", "d1", "d2"]
        assert not list(tmp_path.glob("*.jsonl*"))
    finally:
        release.set()
        taker.close()
        third.close()


def test_a_segment_an_adopter_left_half_shipped_is_adopted_again(tmp_path: Path) -> None:
    """An adopter that dies while shipping leaves ``*.jsonl.adopted`` unlocked: the next process
    adopts it as it would the writer's segment (shipping twice duplicates nothing)."""
    left = tmp_path / "999999999-1-1.jsonl.adopted"
    left.write_bytes(b"".join(encode("db", "c", {"id": f"d{k}"}) for k in range(2)))
    shipped: list[str] = []
    journal = Journal(tmp_path, lambda db, c, lines: shipped.extend(json.loads(x)["d"]["id"] for x in lines),
                      adopt_interval_s=3600)
    try:
        assert journal.catch_up(5)
        assert shipped == ["d0", "d1"] and not left.exists()
    finally:
        journal.close()


def test_settle_waits_for_the_writes_before_it_and_not_for_those_after(tmp_path: Path) -> None:
    """A read of the database after ``settle`` sees this process's writes made before the call
    (a client that fires, then lists decisions, finds its own); writes appended while it waits
    do not hold it up, so a steady stream of them never makes a read wait its whole timeout."""
    gate = threading.Semaphore(0)
    shipped: list[str] = []
    journal: Journal

    def ship(db: str, c: str, lines: list[bytes]) -> None:
        for line in lines:
            assert gate.acquire(timeout=10)
            ident = json.loads(line)["d"]["id"]
            shipped.append(ident)
            if ident == "mine":  # a write that arrives while the reader waits
                journal.append("db", "c", [encode("db", "c", {"id": "after"})])

    journal = Journal(tmp_path, ship, batch=1)
    try:
        journal.append("db", "c", [encode("db", "c", {"id": "mine"})])
        assert not journal.settle(0.2) and shipped == []  # still in the journal: not yet readable
        journal.append("db", "c", [encode("db", "c", {"id": "later"})])
        opener = threading.Timer(0.3, lambda: (gate.release(), gate.release()))  # "mine" and "later" only
        opener.start()
        assert journal.settle(5)  # returns with "after" still waiting for the gate
        assert shipped == ["mine", "later"]
        assert not journal.settle(0.2)  # now "after" is one of this reader's
        gate.release()
        assert journal.settle(5) and shipped == ["mine", "later", "after"]
    finally:
        gate.release()
        journal.close()
