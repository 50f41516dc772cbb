"""Bulkheads and overload: a fast rule set's fire and ``/health`` beside a slow rule set, and 40
connections on the slow set.

Runs ``printeps serve`` (1 worker, as bench/http_bench.py) with the shipped rule sets plus a slow
one (each fire takes ``--slow-ms``, 500 by default, in its then-part) and measures, in the same run:

1. unloaded: the reception fire (2 connections) and ``GET /health`` (1 connection);
2. the same beside the slow set kept busy (4 connections firing it back to back);
3. overload: 40 connections firing the slow set, with the reception fire and ``/health`` beside:
   how many were served, refused with 429/503 (and how fast the refusal came), and the longest wait.

    .venv/bin/python bench/bulkhead_bench.py [--seconds 10] [--slow-ms 500] [--write-docs]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
import tempfile
import time
from pathlib import Path

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from http_bench import free_port, read_response, request_bytes, start_server, teahouse_facts  # noqa: E402
from report import machine_note, write_section  # noqa: E402

SECTION = "## Bulkheads and overload"
SLOW = "slowbench"
SLOW_DRL = """package org.printeps.slowbench;

declare Work
    id : String
    ms : int
end

rule "Take its time"
when
    $w : Work( id == "bench" )
then
    try { Thread.sleep(Math.min($w.getMs(), 5000)); } catch (InterruptedException e) { }
end
"""


async def connection(port: int, req: bytes, until: float, out: list[tuple[int, float]]) -> None:
    """Sends ``req`` back to back until ``until``; appends (status, seconds) per answer. After a
    refusal it waits a second, as a client honouring ``Retry-After`` would (at least that long)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    try:
        while time.perf_counter() < until:
            t0 = time.perf_counter()
            writer.write(req)
            head, _body = await read_response(reader)
            status = int(head[9:12])
            out.append((status, time.perf_counter() - t0))
            if status in (429, 503):
                await asyncio.sleep(1.0)
    finally:
        writer.close()


def p99_ms(samples: list[tuple[int, float]]) -> float:
    ordered = sorted(s for _, s in samples)
    return ordered[min(len(ordered) - 1, int(0.99 * len(ordered)))] * 1000 if ordered else float("nan")


async def phase(port: int, seconds: float, slow_connections: int, slow_ms: int) -> dict[str, list[tuple[int, float]]]:
    fire = request_bytes("POST", "/api/rulesets/reception/fire", json.dumps({"facts": teahouse_facts()}).encode())
    health = request_bytes("GET", "/health", None)
    slow = request_bytes("POST", f"/api/rulesets/{SLOW}/fire",
                         json.dumps({"facts": [{"type": "Work", "id": "bench", "ms": slow_ms}]}).encode())
    until = time.perf_counter() + seconds
    got: dict[str, list[tuple[int, float]]] = {"fire": [], "health": [], "slow": []}
    tasks = [connection(port, fire, until, got["fire"]) for _ in range(2)]
    tasks.append(connection(port, health, until, got["health"]))
    tasks += [connection(port, slow, until, got["slow"]) for _ in range(slow_connections)]
    await asyncio.gather(*tasks)
    return got


def describe(name: str, got: dict[str, list[tuple[int, float]]]) -> dict[str, object]:
    slow = got["slow"]
    refused = [s for c, s in slow if c in (429, 503)]
    return {
        "run": name,
        "fire_p99_ms": round(p99_ms(got["fire"]), 2), "fires": len(got["fire"]),
        "fire_errors": sum(1 for c, _ in got["fire"] if c != 200),
        "health_p99_ms": round(p99_ms(got["health"]), 2),
        "slow_served": sum(1 for c, _ in slow if c == 200),
        "slow_429": sum(1 for c, _ in slow if c == 429), "slow_503": sum(1 for c, _ in slow if c == 503),
        "slow_other": sum(1 for c, _ in slow if c not in (200, 429, 503)),
        "refusal_p99_ms": round(p99_ms([(0, s) for s in refused]), 2) if refused else None,
        "longest_slow_s": round(max((s for _, s in slow), default=0.0), 2),
    }


def render(rows: list[dict[str, object]], seconds: float, slow_ms: int, started: str) -> str:
    lines = [SECTION, "",
             f"`bench/bulkhead_bench.py` ({seconds:g} s per run, {started}, {machine_note()}; the load generator runs "
             f"on the same cores): `printeps serve` (1 worker, defaults: `api.fire_workers: 2`, `api.max_queue: 64`, "
             f"`api.max_wait_s: 5`). The reception fire (2 connections, recorded) and `GET /health` (1 connection) "
             f"unloaded, beside a rule set whose fire takes {slow_ms} ms kept busy by 4 connections, and beside 40 "
             f"connections on that slow set (overload).", "",
             "| run | reception fire p99 ms | fires | /health p99 ms | slow set: served | 429 | 503 | "
             "refusal p99 ms | longest slow answer s |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['run']} | {r['fire_p99_ms']} | {r['fires']} | {r['health_p99_ms']} | {r['slow_served']} | "
                     f"{r['slow_429']} | {r['slow_503']} | {r['refusal_p99_ms'] if r['refusal_p99_ms'] is not None else '-'} | "
                     f"{r['longest_slow_s']} |")
    lines += ["", "Goals: the reception fire's and `/health`'s p99 under 50 ms beside the slow set; under overload "
              "the excess is refused early (429/503 with `Retry-After`) and no request waits more than 15 s."]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--slow-ms", type=int, default=500)
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    port = free_port()
    with tempfile.TemporaryDirectory() as tmp:
        server = start_server(Path(tmp), port)
        try:
            r = httpx.put(f"http://127.0.0.1:{port}/api/rulesets/{SLOW}", json={"files": {"slow.drl": SLOW_DRL}},
                          timeout=300)
            r.raise_for_status()
            asyncio.run(phase(port, 3.0, 0, args.slow_ms))  # warm-up, not counted
            rows = []
            for name, slow_connections in (("unloaded", 0), ("beside a slow set (4 conns)", 4),
                                           ("overload: 40 conns on the slow set", 40)):
                rows.append(describe(name, asyncio.run(phase(port, args.seconds, slow_connections, args.slow_ms))))
                print(json.dumps(rows[-1]), flush=True)
        finally:
            server.terminate()
            server.wait(timeout=60)
    text = render(rows, args.seconds, args.slow_ms, started)
    print(text)
    if args.write_docs:
        write_section(SECTION, text)


if __name__ == "__main__":
    main()
