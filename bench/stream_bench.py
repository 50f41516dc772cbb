"""Benchmark of the stream engine (issue 17); run by hand, results into docs/benchmarks.md.

1. The papers' CustomerDetectionQuery at 20 people × 30 Hz, RANGE 3s STEP 1s: the window step
   (the push that closes a window: assembling it, evaluating, publishing) p50/p99, the fast path
   and the general path (pyoxigraph) side by side, end to end in the engine; rdflib on one window
   as a third peer.
2. Leaving-seat detection (ontology/queries/leaving_seat.rq) over 50 tables × 10 Hz: step p99
   (named windows and FILTER NOT EXISTS: the general path).
3. Growth: step time against window size (1 s … 60 s) and reading rate, both paths, for a
   per-person aggregate query (linear in the window) and the papers' pair query (quadratic).

    .venv/bin/python bench/stream_bench.py [--quick] [--write-docs]

Step times depend on the machine's load (2 shared cores): every step is timed twice, on the wall
clock and as the CPU time of the thread (``time.thread_time``: what the step costs, without the
time other processes held the cores). The load average is printed with the results; compare the
paths measured in the same run, not runs with each other.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import random
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "stream"))

from csparql_scenarios import CUSTOMER_QUERY, ENTRANCE  # noqa: E402
from table_scenarios import LEAVING_SEAT_QUERY, TABLES  # noqa: E402
from table_scenarios import mapper as table_mapper

from gateway.config import StreamSettings  # noqa: E402
from gateway.rdf import Mapper  # noqa: E402
from gateway.rdf.mapping import mappings_from_folder  # noqa: E402
from gateway.stream import StreamEngine  # noqa: E402
from gateway.stream.evaluate import WindowData, evaluate_rdflib  # noqa: E402

PEOPLE = 20
SINGLE_QUERY = """REGISTER QUERY PerPerson AS
PREFIX rdf: <http://www.w3.org/1999/02/22-rdf-syntax-ns#>
PREFIX printeps: <http://printeps.org/cafe/entrance/>
SELECT ?s (COUNT(*) AS ?n) (AVG(?d) AS ?avg) (MIN(?d) AS ?closest)
FROM STREAM <http://printeps.org/cafe/entrance> [RANGE 3s STEP 1s]
WHERE { ?s rdf:type printeps:Customer ; printeps:positionAtTime ?t . ?t printeps:distance ?d . FILTER(?d < 3.3) }
GROUP BY ?s"""


def pct(values: list[float], q: float) -> float:
    values = sorted(values)
    return values[min(len(values) - 1, int(len(values) * q))] if values else float("nan")


def entrance_scenario(people: int, hz: float, seconds: float, seed: int = 1) -> list[tuple[int, dict]]:
    """People approaching, walking past (with noise) and leaving, mixed (Entrance messages)."""
    rnd = random.Random(seed)
    kinds = [rnd.choice(["approach", "past", "leave"]) for _ in range(people)]
    starts = [rnd.uniform(2.0, 5.0) for _ in range(people)]
    out = []
    for k in range(int(seconds * hz)):
        t = k / hz
        customers = []
        for i, kind in enumerate(kinds):
            base = starts[i] + {"approach": -0.4 * t, "past": 0.0, "leave": 0.4 * t}[kind]
            customers.append({"id": f"c{i}", "distance": round(max(0.3, base + rnd.uniform(-0.02, 0.02)), 3)})
        out.append((int(round(t * 1000)), {"id": "entrance1", "number_of_customers": people, "customers": customers}))
    return out


def table_scenario(tables: int, hz: float, seconds: float, seed: int = 2) -> list[tuple[int, dict]]:
    """Each table's sensor at ``hz``: the table itself and every customer there; parties of 1–4
    arrive and leave at random times (a table is free 20–60 s between parties)."""
    rnd = random.Random(seed)
    schedule: dict[str, list[tuple[float, float, int]]] = {}
    for t in range(tables):
        at, parties = rnd.uniform(0, 30), []
        while at < seconds:
            stay = rnd.uniform(30, 120)
            parties.append((at, at + stay, rnd.randint(1, 4)))
            at += stay + rnd.uniform(20, 60)
        schedule[f"table{t + 1}"] = parties
    out = []
    for k in range(int(seconds * hz)):
        now = k / hz
        ts = int(round(now * 1000))
        for table, parties in schedule.items():
            out.append((ts, {"id": table, "type": "Table", "location": table, "x": 0.0, "y": 0.0, "distance": 0.0}))
            for p, (start, end, size) in enumerate(parties):
                if start <= now < end:
                    for c in range(size):
                        out.append((ts, {"id": f"{table}_p{p}_c{c}", "type": "Customer", "location": table,
                                         "x": 1.0 + 0.1 * c, "y": 2.0, "distance": round(0.3 + 0.05 * c, 2)}))
    return out


def run(query: str, stream: str, mapped: list[tuple[int, list]], fast: bool, ontology: str | None = None,
        max_steps: int | None = None) -> dict[str, Any]:
    """Push everything; the time of every push that closed a window (a step) and of the others."""
    settings = StreamSettings(queries_dir=None, fast_path=fast, max_window_triples=10**7,
                              **({"knowledge_dir": str(Path(ontology).parent)} if ontology else {}))
    engine = StreamEngine(settings)
    name = engine.register(query)["name"]
    steps: list[float] = []
    steps_cpu: list[float] = []
    pushes: list[float] = []
    started = time.perf_counter()
    for ts, triples in mapped:
        c0, t0 = time.thread_time(), time.perf_counter()
        report = engine.push(stream, ts, triples)
        dt, dc = (time.perf_counter() - t0) * 1000, (time.thread_time() - c0) * 1000
        if report["evaluated"]:
            steps.append(dt)
            steps_cpu.append(dc)
        else:
            pushes.append(dt)
        if max_steps is not None and len(steps) >= max_steps:
            break
    total = time.perf_counter() - started
    info = engine.query_info(name)
    return {"steps": steps, "cpu": steps_cpu, "pushes": pushes, "total_s": total, "stats": info["stats"],
            "engine": engine,
            "runtime": engine._queries[name]}  # noqa: SLF001 (the bench looks inside)


def fmt(result: dict[str, Any]) -> str:
    s, c = result["steps"], result["cpu"]
    return (f"step p50 {statistics.median(s):.2f} ms, p99 {pct(s, 0.99):.2f} ms, max {max(s):.2f} ms on the wall "
            f"clock; CPU time p50 {statistics.median(c):.2f} ms, p99 {pct(c, 0.99):.2f} ms ({len(s)} steps)")


def _rdflib_child(text: str, window: WindowData, queue: Any) -> None:
    t0 = time.perf_counter()
    rows = len(evaluate_rdflib(text, window).rows)
    queue.put((time.perf_counter() - t0, rows))


def rdflib_window(text: str, window: WindowData, timeout: float) -> float | None:
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    proc = ctx.Process(target=_rdflib_child, args=(text, window, queue))
    proc.start()
    proc.join(timeout)
    if proc.is_alive():
        proc.terminate()
        proc.join()
        return None
    return queue.get()[0]


def papers_query(say: Callable[[str], None], seconds: float, general_seconds: float, rdflib_timeout: float) -> dict:
    msgs = entrance_scenario(PEOPLE, 30, seconds)
    m = Mapper(mappings_from_folder(ROOT / "ontology" / "mappings"))
    mapped = [(ts, m.map(x, ts, "entrance")) for ts, x in msgs]
    fast = run(CUSTOMER_QUERY, ENTRANCE, mapped, True)
    general = run(CUSTOMER_QUERY, ENTRANCE, mapped[: int(general_seconds * 30)], False)
    ratio = statistics.median(general["cpu"]) / statistics.median(fast["cpu"])
    say("### The papers' query, 20 people × 30 Hz, RANGE 3s STEP 1s\n")
    say(f"- fast path: {fmt(fast)} over {seconds:.0f} s of stream ({len(mapped)} messages; "
        f"push without a window close p99 {pct(fast['pushes'], 0.99):.3f} ms; the whole stream in "
        f"{fast['total_s']:.2f} s, {seconds / fast['total_s']:.0f}× real time; fallbacks {fast['stats']['fallbacks']})")
    say(f"- general path (pyoxigraph): {fmt(general)} over {general_seconds:.0f} s of stream; "
        f"median step (CPU) {ratio:.0f}× the fast path's")
    out = {"fast": fast["steps"], "fast_cpu": fast["cpu"], "general": general["steps"], "general_cpu": general["cpu"]}
    if rdflib_timeout > 0:
        runtime = fast["runtime"]
        keep = run(CUSTOMER_QUERY.replace("[RANGE 3s STEP 1s]", "[RANGE 1h STEP 1h]"), ENTRANCE, mapped[:200], True)
        data = keep["engine"].window_data(keep["runtime"], 6000, 6000, None)
        data.stamped = {t: ts for t, ts in data.stamped.items() if 3000 <= ts < 6000}
        data.segments, data.start_ms = None, 3000
        took = rdflib_window(runtime.plan_text, data, rdflib_timeout)
        say("- rdflib, one full window (" + (f"{took * 1000:.0f} ms wall clock, {took * 1000 / statistics.median(fast['steps']):.0f}× "
            "the fast path's median step)" if took is not None else f"did not finish in {rdflib_timeout:.0f} s)"))
    return out


def leaving_seat(say: Callable[[str], None], seconds: float) -> dict:
    msgs = table_scenario(50, 10, seconds)
    m = table_mapper()
    mapped = [(ts, m.map(x, ts, "teahouse_object")) for ts, x in msgs]
    result = run(LEAVING_SEAT_QUERY, TABLES, mapped, True)
    departures = result["stats"]["results"]
    say("\n### Leaving-seat detection, 50 tables × 10 Hz\n")
    say(f"- {len(mapped)} messages ({len(mapped) / seconds:.0f}/s: each table and each customer at it, 10 times a "
        f"second) over {seconds:.0f} s, windows of 2 min and 20 s, STEP 1s, general path (named windows, "
        f"FILTER NOT EXISTS): {fmt(result)}; push p99 {pct(result['pushes'], 0.99):.3f} ms; "
        f"{departures} windows reported departures; the whole stream in {result['total_s']:.1f} s "
        f"({seconds / result['total_s']:.1f}× real time)")
    return {"steps": result["steps"], "cpu": result["cpu"]}


def growth(say: Callable[[str], None], quick: bool) -> dict:
    say("\n### Growth: step time against window size and rate (20 people, STEP 1s)\n")
    say("Per-person aggregate (COUNT/AVG/MIN per person: linear in the window), median step CPU time in ms "
        "(last 5 windows), fast path / general path:\n")
    rates = (1, 10, 30)
    ranges = (1, 5, 15, 30, 60) if not quick else (1, 15)
    say("| window | " + " | ".join(f"{r} Hz" for r in rates) + " |")
    say("|---|" + "---|" * len(rates))
    table: dict[str, Any] = {}
    m = Mapper(mappings_from_folder(ROOT / "ontology" / "mappings"))
    for rng in ranges:
        cells = []
        for hz in rates:
            seconds = rng + 6
            mapped = [(ts, m.map(x, ts, "entrance")) for ts, x in entrance_scenario(PEOPLE, hz, seconds)]
            query = SINGLE_QUERY.replace("[RANGE 3s STEP 1s]", f"[RANGE {rng}s STEP 1s]")
            fast = run(query, ENTRANCE, mapped, True)
            general = run(query, ENTRANCE, mapped, False)
            f, g = statistics.median(fast["cpu"][-5:]), statistics.median(general["cpu"][-5:])
            table[f"single/{rng}s/{hz}Hz"] = (f, g)
            cells.append(f"{f:.1f} / {g:.0f}")
        say(f"| {rng} s | " + " | ".join(cells) + " |")
    say("\nThe papers' pair query (quadratic: every pair of a person's readings in the window), median step "
        "CPU time in ms (last 4 windows), fast path / general path (general only up to 200,000 pairs a window):\n")
    pair_ranges = (1, 3, 5, 10) if not quick else (1, 3)
    say("| window | " + " | ".join(f"{r} Hz" for r in rates) + " |")
    say("|---|" + "---|" * len(rates))
    for rng in pair_ranges:
        cells = []
        for hz in rates:
            seconds = rng + 5
            mapped = [(ts, m.map(x, ts, "entrance")) for ts, x in entrance_scenario(PEOPLE, hz, seconds)]
            query = CUSTOMER_QUERY.replace("[RANGE 3s STEP 1s]", f"[RANGE {rng}s STEP 1s]")
            fast = run(query, ENTRANCE, mapped, True)
            f = statistics.median(fast["cpu"][-4:])
            pairs = PEOPLE * (rng * hz) ** 2
            if pairs <= 200_000:
                general = run(query, ENTRANCE, mapped, False)
                g = statistics.median(general["cpu"][-4:])
                cells.append(f"{f:.1f} / {g:.0f}")
            else:
                g = None
                cells.append(f"{f:.1f} / –")
            table[f"pairs/{rng}s/{hz}Hz"] = (f, g)
        say(f"| {rng} s | " + " | ".join(cells) + " |")
    return table


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="shorter streams, fewer growth points")
    parser.add_argument("--rdflib-timeout", type=float, default=120, help="0: skip rdflib")
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    lines: list[str] = []

    def say(text: str) -> None:
        print(text, flush=True)
        lines.append(text)

    load_before = os.getloadavg()
    started = time.time()
    results = {
        "papers": papers_query(say, 30 if args.quick else 120, 10 if args.quick else 40, args.rdflib_timeout),
        "leaving_seat": leaving_seat(say, 60 if args.quick else 180),
        "growth": growth(say, args.quick),
    }
    load_after = os.getloadavg()
    note = (f"\nMachine: {os.cpu_count()} cores, shared; load average (1 min) {load_before[0]:.1f} at the start and "
            f"{load_after[0]:.1f} at the end of the run ({(time.time() - started) / 60:.0f} min).")
    say(note)
    out = ROOT / "bench" / "results" / "stream_bench.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(json.dumps({"date": time.strftime("%Y-%m-%d"), "load": [load_before, load_after],
                               "results": results}, default=str, indent=1), encoding="utf-8")
    if args.write_docs:
        write_docs(lines)


def write_docs(lines: list[str]) -> None:
    """Replace (or add) the section '## Stream reasoning (C-SPARQL)' in docs/benchmarks.md."""
    path = ROOT / "docs" / "benchmarks.md"
    head = "## Stream reasoning (C-SPARQL)"
    body = (f"{head}\n\n`bench/stream_bench.py`, {time.strftime('%Y-%m-%d')}, 2 shared cores: compare the paths "
            "measured in the same run, not the absolute times.\n\n" + "\n".join(lines) + "\n")
    notes = ROOT / "bench" / "stream_bench_notes.md"
    if notes.exists():  # the hand-written reading of the numbers
        body += "\n" + notes.read_text(encoding="utf-8")
    text = path.read_text(encoding="utf-8") if path.exists() else "# Benchmarks\n"
    if head in text:
        start = text.index(head)
        nxt = text.find("\n## ", start + len(head))
        text = text[:start] + body + ("\n" + text[nxt + 1:] if nxt >= 0 else "")
    else:
        text = text.rstrip("\n") + "\n\n" + body
    path.write_text(text, encoding="utf-8")


if __name__ == "__main__":
    main()
