"""``make bench``: every benchmark, one after the other, each writing its section of docs/benchmarks.md.

Run on an otherwise idle machine (2 cores: anything else running moves the absolute numbers; the
ratios against the peers measured in the same run are what to read). A bench that fails is
reported and the others still run; the exit code says whether all of them ran.

    .venv/bin/python bench/run_all.py [--quick] [--only http,propagation,...]
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent


def benches(quick: bool) -> dict[str, list[str]]:
    """name -> command line (relative to the project root)."""
    seconds = "4" if quick else "10"
    return {
        "engine": ["bench/engine_bench.py", *(["--quick"] if quick else [])],
        "http": ["bench/http_bench.py", "--seconds", seconds, "--write-docs"],
        "bulkheads": ["bench/bulkhead_bench.py", "--seconds", "5" if quick else "10", "--write-docs"],
        "propagation": ["bench/propagation_bench.py", "--rounds", "6" if quick else "20", "--write-docs"],
        "ros": ["bench/ros_latency.py", "60" if quick else "200", "--write-docs"],
        "stream": ["bench/stream_bench.py", *(["--quick", "--rdflib-timeout", "0"] if quick else []), "--write-docs"],
        "sessions": ["bench/session_bench.py", "--seconds", seconds, "--write-docs"],
        "durable": ["bench/durable_sessions.py", *(["--calls", "300", "--facts", "2000", "--since", "200"] if quick else []),
                    "--write-docs"],
        "dialogue": ["bench/dialogue_bench.py", *(["--orders", "20", "--open-orders", "5", "--turns", "50"]
                                                  if quick else []), "--write-docs"],
        "agile": ["bench/agile_loop.py", "--repeat", "1" if quick else "3", "--write", "docs/agile-loop.md"],
        "table2-browser": ["bench/table2_browser.py", "--write", "docs/agile-loop.md"],
        # the longest (10,000 rules, peers included): last, so the others are not held up
        "growth": ["bench/growth_bench.py", *(["--sizes", "100,1000"] if quick else []), "--write"],
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="shorter runs (a smoke test of the benches)")
    ap.add_argument("--only", default="", help="comma-separated names: " + ", ".join(benches(False)))
    args = ap.parse_args()
    chosen = benches(args.quick)
    if args.only:
        unknown = sorted(set(args.only.split(",")) - set(chosen))
        if unknown:
            ap.error(f"unknown bench(es) {unknown}; known: {', '.join(chosen)}")
        chosen = {k: v for k, v in chosen.items() if k in args.only.split(",")}
    failed = []
    for name, cmd in chosen.items():
        print(f"\n=== {name}: {' '.join(cmd)}", flush=True)
        started = time.monotonic()
        if not (ROOT / cmd[0]).exists():
            print(f"--- {name}: {cmd[0]} is missing", flush=True)
            failed.append(name)
            continue
        done = subprocess.run([sys.executable, *cmd], cwd=ROOT)
        print(f"--- {name}: exit {done.returncode} after {time.monotonic() - started:.0f} s", flush=True)
        if done.returncode != 0:
            failed.append(name)
    if failed:
        print(f"\nfailed: {', '.join(failed)}", file=sys.stderr)
        return 1
    print("\nall benchmarks ran; results in docs/benchmarks.md")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
