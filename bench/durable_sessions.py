"""Durable sessions (issue 28): what journalling every session command costs, how long a takeover
takes, and how many journal bytes a command writes.

1. **Cost per call**, in the same run, calls interleaved: a durable session's insert-and-fire
   (``POST …/sessions/{id}/facts`` with ``"fire": true``), the same on a session opened with
   ``"durable": false``, and a stateless fire of the same fact (``POST /api/rulesets/{name}/fire``):
   p50 and p99 of each (the goal: durable p50 at most 1.5x the stateless fire).
2. **Takeover**: a session of ``--facts`` facts (10,000), snapshotted, then ``--since`` commands
   (1,000) after its snapshot; its process is SIGKILLed and a new ``printeps serve`` on the same
   data dir answers the session's first call: that call's time is the rebuild (journal adoption,
   snapshot restore, replay). The goal: under 2 s on 2 cores. Then its first fire (of the
   ``--since`` inserts), beside the same fire of a session never rebuilt holding the same facts, in
   the process later killed (warm) and in the new process (after the takeover): a slow first fire
   after a takeover is then the rebuild's doing only if it is slower than both.
3. **Journal bytes per command**: the journal line of one insert-and-fire entry, encoded exactly as
   the journal writes it, and of a snapshot per fact.

    .venv/bin/python bench/durable_sessions.py [--calls 2000] [--facts 10000] [--since 1000] [--write-docs]

``--calls 50 --facts 500 --since 50`` checks that it works in a minute; ``--ack-after database``
measures the several-hosts setting (a command answered once it is in the database).
"""

from __future__ import annotations

import argparse
import json
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from http_bench import free_port  # noqa: E402
from report import machine_note, write_section  # noqa: E402
from session_bench import FACT, serve_visits  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SECTION = "## Durable sessions"


def serve(home: Path, port: int, snapshot_every: int, ack_after: str = "journal") -> subprocess.Popen:
    """``printeps serve`` on ``home`` (its data dir kept across restarts), once it answers."""
    return serve_visits(home, port, {"max_facts": 10_000_000, "snapshot_every": snapshot_every,
                                     "snapshot_interval_s": 0, "ack_after": ack_after})


def percentiles(samples: list[float]) -> dict[str, float]:
    ordered = sorted(samples)
    return {"n": len(ordered), "p50_ms": statistics.median(ordered) * 1000,
            "p99_ms": ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))] * 1000}


def cost_per_call(c: httpx.Client, calls: int) -> dict[str, dict[str, float]]:
    """Durable, non-durable and stateless insert-and-fire, interleaved call by call."""
    sessions = {kind: c.post("/api/rulesets/visits/sessions", json={"durable": kind == "durable"}).json()["id"]
                for kind in ("durable", "plain")}
    samples: dict[str, list[float]] = {"durable": [], "plain": [], "stateless": []}
    for k in range(calls + 100):  # the first 100 warm up
        for kind, path, body in (
                ("durable", f"/api/rulesets/visits/sessions/{sessions['durable']}/facts", {"facts": [FACT], "fire": True}),
                ("plain", f"/api/rulesets/visits/sessions/{sessions['plain']}/facts", {"facts": [FACT], "fire": True}),
                ("stateless", "/api/rulesets/visits/fire", {"facts": [FACT]})):
            t0 = time.perf_counter()
            r = c.post(path, json=body)
            elapsed = time.perf_counter() - t0
            assert r.status_code in (200, 201), r.text
            if k >= 100:
                samples[kind].append(elapsed)
    for sid in sessions.values():
        c.delete(f"/api/rulesets/visits/sessions/{sid}")
    out = {kind: percentiles(v) for kind, v in samples.items()}
    out["ratio_durable_to_stateless_p50"] = {"x": out["durable"]["p50_ms"] / out["stateless"]["p50_ms"]}
    return out


def fill(c: httpx.Client, sid: str, facts: int, since: int, pad_to: int = 0) -> None:
    """``facts`` facts in batches of 1,000, each fired; fires with nothing to fire up to command
    ``pad_to`` (the snapshot falls due right there); then ``since`` inserts, none fired."""
    batches = max(1, facts // 1000) if facts else 0
    for b in range(batches):
        r = c.post(f"/api/rulesets/visits/sessions/{sid}/facts", json={"fire": True, "facts": [
            {"type": "Visit", "id": f"v{b}-{i}", "party": 1} for i in range(facts // batches)]})
        assert r.status_code == 201, r.text
    for _ in range(pad_to - batches):
        assert c.post(f"/api/rulesets/visits/sessions/{sid}/fire").status_code == 200
    for k in range(since):
        assert c.post(f"/api/rulesets/visits/sessions/{sid}/facts",
                      json={"facts": [{"type": "Visit", "id": f"s{k}", "party": 2}]}).status_code == 201


def timed_fire(c: httpx.Client, sid: str) -> float:
    t0 = time.perf_counter()
    r = c.post(f"/api/rulesets/visits/sessions/{sid}/fire")
    elapsed = time.perf_counter() - t0
    assert r.status_code == 200, r.text
    return elapsed


def takeover(home: Path, facts: int, since: int) -> dict[str, float]:
    """A session of ``facts`` facts snapshotted, ``since`` commands after it, SIGKILL, a new
    process: the time of its first call on the session (the rebuild), then of its first fire (the
    ``since`` inserts). Beside it, the same fire of a session never rebuilt: in the process that
    was then killed (warm, never killed; measured before the kill), and in the new process after
    the takeover; each of those sessions holds the same facts, and is not durable (no snapshot
    rebuilds it behind the measure)."""
    every = since + 1  # due once, right after the padding: the `since` inserts then make no snapshot
    port = free_port()
    proc = serve(home, port, snapshot_every=every)
    url = f"http://127.0.0.1:{port}"
    with httpx.Client(base_url=url, timeout=600) as c:
        sid = c.post("/api/rulesets/visits/sessions", json={}).json()["id"]
        fill(c, sid, facts, 0, pad_to=every)
        info = c.get(f"/api/rulesets/visits/sessions/{sid}").json()
        assert info["commands_since_snapshot"] == 0 and info["last_snapshot"], info
        fill(c, sid, 0, since)
        held = c.get(f"/api/rulesets/visits/sessions/{sid}").json()
        control = c.post("/api/rulesets/visits/sessions", json={"durable": False}).json()["id"]
        fill(c, control, facts, since)
        never_killed = timed_fire(c, control)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    port = free_port()
    proc = serve(home, port, snapshot_every=every)
    try:
        with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=600) as c:
            t0 = time.perf_counter()
            r = c.get(f"/api/rulesets/visits/sessions/{sid}")
            elapsed = time.perf_counter() - t0
            assert r.status_code == 200 and r.json()["fact_count"] == held["fact_count"], r.text
            first_fire = timed_fire(c, sid)
            fresh = c.post("/api/rulesets/visits/sessions", json={"durable": False}).json()["id"]
            fill(c, fresh, facts, since)
            in_taker = timed_fire(c, fresh)
            c.delete(f"/api/rulesets/visits/sessions/{sid}")
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)
    return {"facts": held["fact_count"], "commands_since_snapshot": held["commands_since_snapshot"],
            "takeover_s": elapsed, "first_fire_after_s": first_fire, "same_fire_never_killed_s": never_killed,
            "same_fire_in_taker_never_rebuilt_s": in_taker}


def journal_bytes() -> dict[str, float]:
    """The journal line of one insert-and-fire entry and a snapshot's bytes per fact, encoded as
    the journal writes them (gateway.store.journal.encode of the stored body)."""
    from gateway.engine.durable import batch_entry
    from gateway.store.journal import encode
    from gateway.store.store import _body

    commands = [{"op": "insert", "facts": [FACT], "ep": "DEFAULT"}, {"op": "fire", "max": -1}]
    results = [{"i": 0, "op": "insert", "handles": ["0:12345:1234567890:1234567890:12345:DEFAULT:NON_TRAIT:org.printeps.bench.Visit"]},
               {"i": 1, "op": "fire", "fire": {"fireCount": 2}}]
    entry = batch_entry(12345, commands, results, 0, lambda text: text)
    doc = {"_id": f"visits/s1-abc-1/ep/{entry['seq']}", "key": "visits/s1-abc-1/ep", "ruleset": "visits",
           "session": "s1-abc-1", "epoch": "ep", **entry}
    line = encode("printeps", "session_log", _body(doc, "session_entry", "gateway", "host:1"))
    fact = {"ep": "DEFAULT", "keys": ["12345:1234567890"], "fact": {"type": "Visit", "id": "v12345", "party": 1}}
    return {"entry_bytes": len(line), "snapshot_bytes_per_fact": len(json.dumps(fact, separators=(",", ":"))) + 1}


def report(note: str, cost: dict, take: dict, size: dict) -> str:
    lines = [SECTION, "", f"`bench/durable_sessions.py` ({note}). Calls interleaved one by one over one keep-alive "
             "connection; the gateway as `printeps serve` (its own JVM, embedded database).", "",
             "| Call | p50 ms | p99 ms |", "|---|---|---|"]
    for kind, label in (("durable", "durable session: insert + fire"), ("plain", "non-durable session: insert + fire"),
                        ("stateless", "stateless fire")):
        lines.append(f"| {label} | {cost[kind]['p50_ms']:.2f} | {cost[kind]['p99_ms']:.2f} |")
    lines += ["", f"Durable p50 / stateless p50: **{cost['ratio_durable_to_stateless_p50']['x']:.2f}x** (goal: at most 1.5x).", "",
              f"Takeover of a session of {take['facts']:,} facts with {take['commands_since_snapshot']:,} commands since its "
              f"snapshot (SIGKILL, a new process on the same data dir, its first call): **{take['takeover_s']:.2f} s** "
              f"(goal: under 2 s); its first fire after (the {take['commands_since_snapshot']:,} inserts sent without a "
              f"fire): {take['first_fire_after_s'] * 1000:.0f} ms. The same fire of a session never rebuilt, same facts: "
              f"{take['same_fire_never_killed_s'] * 1000:.0f} ms in the process later killed (warm, before the kill), "
              f"{take['same_fire_in_taker_never_rebuilt_s'] * 1000:.0f} ms in the new process after the takeover.", "",
              f"Journal: {size['entry_bytes']} bytes per insert-and-fire entry; a snapshot "
              f"{size['snapshot_bytes_per_fact']} bytes per fact."]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--calls", type=int, default=2000)
    parser.add_argument("--facts", type=int, default=10_000)
    parser.add_argument("--since", type=int, default=1000)
    parser.add_argument("--ack-after", choices=("journal", "database"), default="journal",
                        help="sessions.ack_after of the cost-per-call server (database: the several-hosts guarantee)")
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    note = machine_note()
    with tempfile.TemporaryDirectory() as tmp:
        port = free_port()
        proc = serve(Path(tmp) / "cost", port, snapshot_every=1000, ack_after=args.ack_after)
        try:
            with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=60) as c:
                cost = cost_per_call(c, args.calls)
        finally:
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout=60)
        take = takeover(Path(tmp) / "takeover", args.facts, args.since)
    size = journal_bytes()
    text = report(f"{note}; sessions.ack_after: {args.ack_after}", cost, take, size)
    print(text)
    print(json.dumps({"cost": cost, "takeover": take, "journal": size}, indent=1))
    if args.write_docs:
        write_section(SECTION, text)


if __name__ == "__main__":
    main()
