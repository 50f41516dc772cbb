"""The cost of handing a fire from the event loop to a thread: which hand-off the bulkheads use.

In one process (uvloop, as `printeps serve`), 8 asyncio tasks fire the reception rule set's
5-fact teahouse request (not recorded) back to back, through each hand-off in turn, interleaved
over several rounds so a busy spell of the shared machine hits each alike:

- ``inline``: ``engine.fire`` on the event loop (the old ``api.inline_fire: true``; no isolation);
- ``pool``: ``loop.run_in_executor`` on a 4-thread ``ThreadPoolExecutor`` (the old ``inline_fire: false``);
- ``to_thread``: ``anyio.to_thread.run_sync`` (FastAPI's threadpool, what a sync route costs);
- ``bulkhead``: :class:`gateway.engine.bulkhead.Bulkhead` (2 threads, a ``SimpleQueue``, one
  ``call_soon_threadsafe`` back).

    .venv/bin/python bench/handoff_bench.py [--seconds 2] [--rounds 3]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Awaitable, Callable

import anyio.to_thread
import uvloop

sys.path.insert(0, str(Path(__file__).resolve().parent))
from http_bench import RULES, teahouse_facts  # noqa: E402

from gateway.config import Settings  # noqa: E402
from gateway.engine import Engine  # noqa: E402
from gateway.engine.bulkhead import Bulkhead  # noqa: E402


async def drive(call: Callable[[], Awaitable[Any]], seconds: float, tasks: int = 8) -> dict[str, float]:
    latencies: list[float] = []
    until = time.perf_counter() + seconds

    async def one() -> None:
        while time.perf_counter() < until:
            t0 = time.perf_counter()
            await call()
            latencies.append(time.perf_counter() - t0)

    start = time.perf_counter()
    await asyncio.gather(*(one() for _ in range(tasks)))
    elapsed = time.perf_counter() - start
    ordered = sorted(latencies)
    return {"per_s": len(ordered) / elapsed, "p50_ms": ordered[len(ordered) // 2] * 1000,
            "p99_ms": ordered[int(0.99 * len(ordered))] * 1000, "mean_ms": statistics.fmean(ordered) * 1000}


async def main_async(seconds: float, rounds: int) -> dict[str, list[dict[str, float]]]:
    with tempfile.TemporaryDirectory() as tmp:
        engine = Engine(Settings.model_validate({"data_dir": tmp, "engine": {"rules_dir": str(RULES)}}))
        engine.seed(engine.settings.engine.rules_dir)
        facts = teahouse_facts()

        def fire() -> Any:
            return engine.fire("reception", facts, record=False)

        loop = asyncio.get_running_loop()
        pool = ThreadPoolExecutor(max_workers=4)
        bulkhead = Bulkhead("reception", workers=2, max_queue=64, max_wait_s=5.0)

        async def inline() -> Any:
            return fire()

        ways: dict[str, Callable[[], Awaitable[Any]]] = {
            "inline": inline,
            "pool": lambda: loop.run_in_executor(pool, fire),
            "to_thread": lambda: anyio.to_thread.run_sync(fire),
            "bulkhead": lambda: bulkhead.run(fire),
        }
        for way in ways.values():  # warm-up: the JVM's JIT, the threads
            await drive(way, 1.0)
        results: dict[str, list[dict[str, float]]] = {name: [] for name in ways}
        for _ in range(rounds):
            for name, way in ways.items():
                results[name].append(await drive(way, seconds))
        pool.shutdown()
        return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=2.0)
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args()
    results = uvloop.run(main_async(args.seconds, args.rounds))
    print("| hand-off | fires/s (best of rounds) | median of rounds | p50 ms | p99 ms |")
    print("|---|---|---|---|---|")
    for name, runs in results.items():
        best = max(runs, key=lambda r: r["per_s"])
        median = statistics.median(r["per_s"] for r in runs)
        print(f"| {name} | {best['per_s']:.0f} | {median:.0f} | {best['p50_ms']:.2f} | {best['p99_ms']:.2f} |")
    print(json.dumps(results))


if __name__ == "__main__":
    main()
