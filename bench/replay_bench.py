"""Replay, explain and trace on the 32-rule reception set, against the REST fires that recorded the decisions.

One gateway in this process (real JVM, the embedded MongoDB-protocol server, uvicorn on loopback):

1. **Record**: N REST fires (``POST /api/rulesets/reception/fire``, one after the other, over HTTP)
   on generated parties (1 to 6 guests of random ages and genders): the peer is their time.
2. **Replay**: ``POST /api/rulesets/reception/replay`` of those N decisions on a draft that moves
   the child/teenager age bound (12 -> 10), synchronously: time, decisions per second, and the
   ratio to the fires (the issue's goal: under half their time).
3. **Explain**: ``POST /api/rulesets/reception/explain`` on the examples' facts: the first call
   (the diagnostic queries' build) and then p50/p99 over repeated calls (goal: under 50 ms).
4. **Trace**: ``GET /api/traces/{id}`` of REST fires' request ids with the N decisions stored
   (the decisions are indexed by ``(correlation_id, _id)``: a trace does not scan them).

    .venv/bin/python bench/replay_bench.py [--n 10000] [--explain 200] [--write]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import statistics
import sys
import tempfile
import time
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "api"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from report import machine_note, write_section  # noqa: E402

SECTION = "## Replay, explain and trace"


def party(rng: random.Random, n: int) -> list[dict]:
    size = rng.randint(1, 6)
    facts = [{"type": "Entrance", "id": f"e{n}", "number_of_customers": size},
             {"type": "Robot", "id": "pepper", "position": "entrance"}]
    for k in range(size):
        facts.append({"type": "Customer", "id": f"c{n}-{k}", "entrance": f"e{n}", "age": rng.randint(1, 80),
                      "gender": rng.choice(["male", "female"]), "distance": 1.8})
    return facts


def pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def run(n: int, explains: int, traces: int, store_timeout_ms: int = 1000) -> dict:
    from gateway.app import build_gateway
    from gateway.config import Settings
    from gateway.engine.ruleset import read_folder
    from gateway.store.embedded import EmbeddedMongo
    from gateway.store.store import InformationState

    from api_helpers import ServerThread

    tmp = Path(tempfile.mkdtemp(prefix="replay-bench-"))
    mongo = EmbeddedMongo(tmp / "mongo")
    mongo.start()
    store = InformationState(mongo.uri, "bench", tmp / "journal", backend="embedded", timeout_ms=store_timeout_ms)
    settings = Settings.model_validate({"data_dir": str(tmp / "var"),
                                        "engine": {"rules_dir": str(ROOT / "rules" / "drl")},
                                        "streams": {"queries_dir": None}})
    started_at = time.perf_counter()
    gateway = build_gateway(settings, store=store, ros=False, warm_up=False)
    server = ServerThread(gateway.app).start()
    out: dict = {"n": n, "load_before": os.getloadavg()[0]}
    try:
        http = httpx.Client(base_url=server.url, timeout=600)
        rng = random.Random(29)
        parties = [party(rng, i) for i in range(n)]
        for facts in parties[:100]:  # warm the fire path; the replay takes the newest n decisions only
            http.post("/api/rulesets/reception/fire", json={"facts": facts}).raise_for_status()
        started = time.perf_counter()
        for i, facts in enumerate(parties):
            answer = http.post("/api/rulesets/reception/fire", json={"facts": facts},
                               headers={"X-Request-ID": f"bench-{i}"})
            answer.raise_for_status()
        out["fire_s"] = time.perf_counter() - started
        store.flush(120)
        files = read_folder(ROOT / "rules" / "drl" / "reception")
        draft = {k: v.replace("aged between 4 and 12", "aged between 4 and 10")
                 .replace("aged between 13 and 19", "aged between 11 and 19") for k, v in files.items()}
        assert draft != files
        http.post("/api/rulesets/reception/replay", json={"files": draft, "limit": 10}).raise_for_status()  # compile
        started = time.perf_counter()
        replay = http.post("/api/rulesets/reception/replay", json={"files": draft, "limit": n})
        out["replay_s"] = time.perf_counter() - started
        replay.raise_for_status()
        body = replay.json()
        assert body["replayed"] == n, body.get("note")
        out.update(replayed=body["replayed"], changed=body["changed"])
        examples = json.loads(files["examples.json"])
        # the live version's explain queries are built in the background when it loads
        # (engine.explain_prebuild); the first explanation after that compiles nothing
        while not gateway.engine.explain_ready(files):
            time.sleep(0.2)
        out["prebuilt_after_start_s"] = time.perf_counter() - started_at
        builds = gateway.engine.explain_builds()
        started = time.perf_counter()
        http.post("/api/rulesets/reception/explain", json={"facts": examples[0]["facts"]}).raise_for_status()
        out["explain_first_s"] = time.perf_counter() - started
        times = []
        for k in range(explains):
            facts = examples[k % len(examples)]["facts"]
            started = time.perf_counter()
            http.post("/api/rulesets/reception/explain", json={"facts": facts}).raise_for_status()
            times.append((time.perf_counter() - started) * 1000)
        assert gateway.engine.explain_builds() == builds, "an explanation built its queries"
        cpu = [c for _wall, c in gateway.engine.explain_timings()[-explains:]]
        out.update(explain_p50_ms=statistics.median(times), explain_p99_ms=pct(times, 0.99),
                   explain_cpu_p50_ms=statistics.median(cpu), explain_cpu_p99_ms=pct(cpu, 0.99),
                   load_explain=os.getloadavg()[0])
        times = []
        for k in range(traces):
            started = time.perf_counter()
            http.get(f"/api/traces/bench-{rng.randrange(n)}").raise_for_status()
            times.append((time.perf_counter() - started) * 1000)
        out.update(trace_p50_ms=statistics.median(times), trace_p99_ms=pct(times, 0.99))
    finally:
        server.stop()
        gateway.close()
        store.close()
        mongo.stop()
    return out


def section(r: dict, note: str) -> str:
    ratio = r["replay_s"] / r["fire_s"]
    return f"""{SECTION}

`bench/replay_bench.py --n {r['n']}` ({note}). One gateway (uvicorn on loopback, embedded
MongoDB-protocol server), the 32-rule reception set; {r['n']} parties of 1 to 6 guests fired over REST
one after the other, then replayed on a draft that moves the child age bound (12 → 10).

| what | time | per decision / call | vs the REST fires |
|---|---|---|---|
| {r['n']} REST fires that recorded the decisions (the peer) | {r['fire_s']:.2f} s | {r['fire_s'] / r['n'] * 1000:.2f} ms | 1.00 |
| replay of those {r['replayed']} decisions on the draft (one synchronous request; {r['changed']} changed) | {r['replay_s']:.2f} s | {r['replay_s'] / r['replayed'] * 1000:.3f} ms | **{ratio:.2f}** (goal < 0.5) |
| explain queries built in the background after the gateway started (`engine.explain_prebuild`) | ready {r['prebuilt_after_start_s']:.1f} s after start | | |
| explain, first call of the version (its queries already built: no compile) | {r['explain_first_s'] * 1000:.0f} ms | | |
| explain, 32 rules, over HTTP, p50 / p99 (load average {r['load_explain']:.1f}) | | {r['explain_p50_ms']:.1f} / {r['explain_p99_ms']:.1f} ms (goal < 50 ms) | |
| explain, 32 rules, CPU time of the explanation (explain thread, JVM included), p50 / p99 | | {r['explain_cpu_p50_ms']:.1f} / {r['explain_cpu_p99_ms']:.1f} ms | |
| trace read with {r['n']} decisions stored, p50 / p99 | | {r['trace_p50_ms']:.1f} / {r['trace_p99_ms']:.1f} ms | |

A replay reads the decisions a page (1,000) at a time and fires each in a fresh stateless session
in-process: no HTTP, no recording, no journal write per decision — that is where it saves on the
fires that made them. The trace finds its decisions through the `(correlation_id, _id)` index,
so its cost does not grow with the decisions kept.
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, default=10_000, help="decisions to record and replay")
    parser.add_argument("--explain", type=int, default=200, help="timed explain calls")
    parser.add_argument("--traces", type=int, default=50, help="timed trace reads")
    parser.add_argument("--write", action="store_true", help="write the section of docs/benchmarks.md")
    parser.add_argument("--store-timeout-ms", type=int, default=1000,
                        help="the store's timeout (store.timeout_ms; raise it on a loaded machine, where the "
                             "embedded database answers a replay's reads slower than the default allows)")
    parser.add_argument("--note", default="", help="added to the machine note (e.g. why the run is small)")
    args = parser.parse_args()
    note = machine_note() + (f"; {args.note}" if args.note else "")
    result = run(args.n, args.explain, args.traces, args.store_timeout_ms)
    print("BENCH-RESULT " + json.dumps(result))
    text = section(result, note)
    print(text)
    if args.write:
        write_section(SECTION, text)


if __name__ == "__main__":
    main()
