"""Benchmark: Table 2's sixteen change requests, submitted live to a running gateway.

For each repetition a fresh gateway is started in a fresh process (a new JVM: the engine's compile
cache must not serve a repeated edit; engine + rule sets + workflows + reasoner, robots and humans
simulated) and the sixteen scenarios of ``tests/agile_harness.py`` are applied in the
paper's order; per scenario we record the edit size and the machine time from submit until the
robots' behaviour shows the change. The peer measured in the same run is the conventional way to
apply a change: restart the gateway process (``printeps serve``) until it answers again.

    .venv/bin/python bench/agile_loop.py [--repeat 3] [--write docs/agile-loop.md]

Results are ratios: our submit-to-live time against the restart measured in the same run, and
against the papers' (human) modification times. ``--write`` replaces the measured table between
the ``<!-- agile-table -->`` markers of the given file.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx

from gateway.config import PROJECT_ROOT

sys.path.insert(0, str(PROJECT_ROOT / "tests"))  # the agile harness is test support (tests/agile_harness.py)

from agile_harness import Measurement, apply, running_gateway, scenarios  # noqa: E402

MARK_START, MARK_END = "<!-- agile-table -->", "<!-- /agile-table -->"


def paper_seconds(text: str) -> float:
    """'16:22+5:38' -> 1320.0 (m:ss, summed)."""
    total = 0.0
    for part in text.split("+"):
        minutes, seconds = part.split(":")
        total += int(minutes) * 60 + int(seconds)
    return total


def restart_seconds(workdir: Path) -> float:
    """Start ``printeps serve`` as its own process and wait until the workflows answer (then stop it)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = dict(os.environ, PRINTEPS_DATA_DIR=str(workdir / "restart-var"))
    t0 = time.perf_counter()
    proc = subprocess.Popen([str(Path(sys.executable).parent / "printeps"), "serve", "--host", "127.0.0.1",
                             "--port", str(port)], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            try:
                if httpx.get(f"http://127.0.0.1:{port}/api/workflows", timeout=2).status_code == 200:
                    return time.perf_counter() - t0
            except httpx.HTTPError:
                pass
            if proc.poll() is not None:
                raise RuntimeError("printeps serve exited")
            time.sleep(0.05)
        raise RuntimeError("printeps serve did not answer in 120 s")
    finally:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            proc.kill()


def table(runs: list[list[Measurement]], restarts: list[float]) -> str:
    restart_ms = statistics.median(restarts) * 1e3
    lines = [
        f"Median over {len(runs)} fresh gateway processes; peer: restarting the gateway, median "
        f"{restart_ms / 1e3:.1f} s in the same run.",
        "",
        "| ID | Suggestion | Cat. | Paper (human, m:ss) | Edit | Lines ± | Chars | Submit → live (ms, median / max) "
        "| vs restart | vs paper | Failed requests |",
        "|---:|---|---|---:|---|---:|---:|---:|---:|---:|---:|",
    ]
    for i, first in enumerate(runs[0]):
        same = [run[i] for run in runs]
        live = [m.submit_to_live_ms for m in same]
        median = statistics.median(live)
        lines.append(
            f"| {first.id} | {first.suggestion} | {first.category} | {first.paper_time} | {first.edit} | "
            f"{first.lines_changed} | {first.chars_changed} | {median:.0f} / {max(live):.0f} | "
            f"{median / restart_ms:.3f}× | 1/{paper_seconds(first.paper_time) * 1e3 / median:,.0f} | "
            f"{sum(len(m.failed_requests) for m in same)} |")
    worst = max(m.submit_to_live_ms for run in runs for m in run)
    lines += ["", f"Slowest submit → live of all: {worst:.0f} ms (target < 2000 ms); "
                  f"all {len(runs[0])} live with no restart."]
    return "\n".join(lines)


def one_repetition(out: Path) -> None:
    """Restart peer + one replay of the sixteen scenarios, in this (fresh) process; JSON to ``out``."""
    with tempfile.TemporaryDirectory(prefix="agile-") as tmp:
        restart = restart_seconds(Path(tmp))
        with running_gateway(Path(tmp) / "live") as gw:
            measured = [apply(gw, scenario) for scenario in scenarios()]
    out.write_text(json.dumps({"restart_s": restart, "measurements": [dataclasses.asdict(m) for m in measured]}))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--write", type=Path, default=None, help="markdown file with the agile-table markers")
    ap.add_argument("--single", type=Path, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.single:
        one_repetition(args.single)
        return 0
    runs: list[list[Measurement]] = []
    restarts: list[float] = []
    with tempfile.TemporaryDirectory(prefix="agile-bench-") as tmp:
        for rep in range(args.repeat):
            out = Path(tmp) / f"rep{rep}.json"
            subprocess.run([sys.executable, __file__, "--single", str(out)], check=True, timeout=600,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            data = json.loads(out.read_text())
            restarts.append(data["restart_s"])
            runs.append([Measurement(**m) for m in data["measurements"]])
            print(f"repetition {rep + 1}: restart {restarts[-1]:.1f} s, slowest live "
                  f"{max(m.submit_to_live_ms for m in runs[-1]):.0f} ms", file=sys.stderr, flush=True)
    text = table(runs, restarts)
    print(text)
    if args.write:
        doc = args.write.read_text(encoding="utf-8")
        start, end = doc.index(MARK_START) + len(MARK_START), doc.index(MARK_END)
        args.write.write_text(doc[:start] + "\n" + text + "\n" + doc[end:], encoding="utf-8")
    return 0


if __name__ == "__main__":
    os.chdir(PROJECT_ROOT)
    raise SystemExit(main())
