"""Before/after comparison of two git trees of the gateway in one run (issue 27): the in-process
engine fire, the REST recorded fire (8 and 2 connections) and the KIE batch, the stream engine's
window step for the papers' query, and the ROS reading → Speak latency.

Why interleaved: the machine is shared, so its load drifts during a run; rounds alternate the trees
(before, after, after, before, ...) so both see the same drift, and the table reports medians over
rounds and the after/before ratio of the same run. Each measure runs the tree's own code: a child
process with ``PYTHONPATH=<tree>`` and ``cwd=<tree>`` (the existing benches' functions drive it).

    .venv/bin/python bench/compare_trees.py --before /work/main --after /work/wt/integ \
        [--budget 600] [--rounds N] [--seconds 5] [--rest-seconds 20] [--stream-seconds 20] [--ros-trials 30] [--write-docs]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import http_bench as hb
from report import machine_note, write_section

SECTION = "## Before and after the restructuring (issue 27)"
ORDER = ("before", "after", "after", "before")  # repeated: each pair of rounds sees the same drift
# (measure, unit, True when higher is better)
METRICS: list[tuple[str, str, bool]] = [
    ("engine fire p50", "ms", False), ("engine fire req/s", "/s", True),
    ("REST fire 8 conn req/s", "/s", True), ("REST fire 8 conn p99", "ms", False),
    ("REST fire 2 conn req/s", "/s", True), ("REST fire 2 conn p50", "ms", False),
    ("KIE batch 8 conn req/s", "/s", True), ("KIE batch 8 conn p99", "ms", False),
    ("stream step p50 (wall)", "ms", False), ("stream step p50 (CPU)", "ms", False),
    ("ROS reading → Speak median", "ms", False), ("ROS reading → Speak p99", "ms", False),
]
STREAM_CHILD = (
    "import json,statistics,sys;sys.path.insert(0,'bench');import stream_bench as s\n"
    "r=s.papers_query(lambda _:None,float(sys.argv[1]),float(sys.argv[2]),0)\n"
    "print('COMPARE '+json.dumps({'wall':statistics.median(r['fast']),'cpu':statistics.median(r['fast_cpu'])}))\n"
)
ROS_LINE = re.compile(r"reading -> Speak at robot \(gateway\)\s+n=\d+\s+median\s+([\d.]+) ms\s+p99\s+([\d.]+) ms")


def use_tree(tree: Path) -> None:
    """Point http_bench's children (server, in-process fire) at ``tree``: its code, rules, cwd."""
    hb.ROOT, hb.RULES = tree, tree / "rules" / "drl"
    os.environ["PYTHONPATH"] = str(tree)


def child(tree: Path, args: list[str], timeout: float) -> str:
    """Run ``python args`` in ``tree`` with that tree's code; its stdout (the error's tail if it fails)."""
    done = subprocess.run([sys.executable, *args], check=False, cwd=tree, env={**os.environ, "PYTHONPATH": str(tree)},
                          capture_output=True, text=True, timeout=timeout)
    if done.returncode != 0:
        raise RuntimeError(f"{args[0]} failed in {tree} (exit {done.returncode}): {done.stderr[-2000:]}")
    return done.stdout


def engine(tree: Path, work: Path, args: argparse.Namespace) -> dict[str, float]:
    r = hb.in_process_fire(work, hb.teahouse_facts(), args.seconds, args.engine_warm_up)
    return {"engine fire p50": r["p50_ms"], "engine fire req/s": r["rps"]}


def rest(tree: Path, work: Path, args: argparse.Namespace) -> dict[str, float]:
    facts = hb.teahouse_facts()
    fire = hb.request_bytes("POST", "/api/rulesets/reception/fire", json.dumps({"facts": facts}).encode())
    kie = hb.request_bytes("POST", "/kie-server/services/rest/server/containers/instances/reception",
                           json.dumps(hb.kie_batch(facts)).encode())
    with contextlib.redirect_stdout(sys.stderr):  # its progress lines: stdout keeps one JSON line per round
        rows = hb.measure(work / "server", [("fire8", fire, 8, b'"decision_id"'), ("fire2", fire, 2, b'"decision_id"'),
                                            ("kie8", kie, 8, b'"SUCCESS"')], args.rest_seconds)
    errors = sum(r["errors"] for r in rows.values())
    if errors:
        raise RuntimeError(f"REST run in {tree}: {errors} failed requests")
    return {"REST fire 8 conn req/s": rows["fire8"]["rps"], "REST fire 8 conn p99": rows["fire8"]["p99_ms"],
            "REST fire 2 conn req/s": rows["fire2"]["rps"], "REST fire 2 conn p50": rows["fire2"]["p50_ms"],
            "KIE batch 8 conn req/s": rows["kie8"]["rps"], "KIE batch 8 conn p99": rows["kie8"]["p99_ms"]}


def stream(tree: Path, work: Path, args: argparse.Namespace) -> dict[str, float]:
    out = child(tree, ["-c", STREAM_CHILD, str(args.stream_seconds), str(args.general_seconds)], 600)
    line = next((x for x in out.splitlines() if x.startswith("COMPARE ")), None)
    if line is None:
        raise RuntimeError(f"no result line from the stream child in {tree}: {out[-1000:]}")
    data = json.loads(line[8:])
    return {"stream step p50 (wall)": data["wall"], "stream step p50 (CPU)": data["cpu"]}


def ros(tree: Path, work: Path, args: argparse.Namespace) -> dict[str, float]:
    out = child(tree, ["bench/ros_latency.py", str(args.ros_trials)], 900)
    found = ROS_LINE.search(out)
    if not found:
        raise RuntimeError(f"no latency line in ros_latency.py's output from {tree}: {out[-1000:]}")
    return {"ROS reading → Speak median": float(found[1]), "ROS reading → Speak p99": float(found[2])}


MEASURES: dict[str, Callable[[Path, Path, argparse.Namespace], dict[str, float]]] = {
    "engine": engine, "rest": rest, "stream": stream, "ros": ros}


def one_round(n: int, side: str, tree: Path, work: Path, args: argparse.Namespace) -> dict:
    """Every chosen measure once against ``tree``; the round's JSON record."""
    use_tree(tree)
    record: dict = {"round": n, "tree": side, "time": time.strftime("%H:%M:%S"), "load": round(os.getloadavg()[0], 2)}
    t0 = time.monotonic()
    for name in args.measures:
        try:
            record.update({k: round(v, 3) for k, v in MEASURES[name](tree, work / f"r{n}-{name}", args).items()})
        except (RuntimeError, subprocess.SubprocessError, OSError, ValueError) as exc:  # one failure loses no round
            record[f"error {name}"] = str(exc)[-500:]
    record["seconds"] = round(time.monotonic() - t0, 1)
    return record


def report(records: list[dict], args: argparse.Namespace, note: str) -> str:
    """The markdown: medians per tree, after/before ratio, and the load at every round."""
    lines = ["| measure | before (median) | after (median) | after/before | better when | as good? |",
             "|---|---|---|---|---|---|"]
    for metric, unit, higher in METRICS:
        side = {s: [r[metric] for r in records if r["tree"] == s and metric in r] for s in ("before", "after")}
        if not side["before"] or not side["after"]:
            continue
        b, a = statistics.median(side["before"]), statistics.median(side["after"])
        ratio = a / b if b else float("nan")
        ok = ratio >= 1 if higher else ratio <= 1
        lines.append(f"| {metric} | {b:.2f} {unit} | {a:.2f} {unit} | {ratio:.2f} | "
                     f"{'higher' if higher else 'lower'} | {'yes' if ok else 'no'} |")
    errors = [f"- round {r['round']} ({r['tree']}): {k}: {v}" for r in records for k, v in r.items()
              if k.startswith("error ")]
    loads = ", ".join(f"{r['round']} {r['tree']} {r['time']} load {r['load']:.1f}" for r in records)
    head = (f"`bench/compare_trees.py --before {args.before} --after {args.after} --rounds {args.rounds} "
            f"--budget {args.budget:.0f} --seconds {args.seconds:g} --rest-seconds {args.rest_seconds:g} "
            f"--stream-seconds {args.stream_seconds:g} "
            f"--ros-trials {args.ros_trials} --engine-warm-up {args.engine_warm_up:g} --measures {','.join(args.measures)}`, {time.strftime('%Y-%m-%d %H:%M')} UTC, {note}. Rounds interleaved "
            f"(before, after, after, before, ...); each measure runs the tree's own code (PYTHONPATH and cwd = the "
            f"tree); medians over each tree's rounds; the ratio is after/before in the same run.")
    return "\n".join([SECTION, "", head, "", *lines, "", f"Load average (1 min) at the start of each round: {loads}.",
                      *(["", "Failed measures (not in the medians):", *errors] if errors else [])])


def fits(records: list[dict], start: float, budget: float) -> bool:
    """Whether one more pair of rounds, as long as the mean round so far, ends within the budget."""
    if not records:
        return True
    mean = statistics.fmean(r["seconds"] for r in records)
    return time.monotonic() - start + 2 * mean <= budget


def parse() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", type=Path, required=True, help="tree before the change (a git checkout)")
    parser.add_argument("--after", type=Path, required=True, help="tree after the change; --write-docs writes here")
    parser.add_argument("--budget", type=float, default=600,
                        help="seconds for the whole run: a new pair of rounds starts only if it should end within it")
    parser.add_argument("--rounds", type=int, default=0, help="at most this many rounds (even; 0: the budget decides)")
    parser.add_argument("--seconds", type=float, default=5.0, help="per engine run")
    parser.add_argument("--rest-seconds", type=float, default=20.0,
                        help="per REST run: 5 s windows after the 8 s warm-up still caught the JIT compiling and the "
                             "shared machine's drift (the same tree measured 1,300-1,860 req/s; docs/benchmarks.md)")
    parser.add_argument("--engine-warm-up", type=float, default=10.0,
                        help="seconds of in-process fires before the engine measure (the JIT still compiles after 3 s)")
    parser.add_argument("--stream-seconds", type=float, default=20.0, help="stream length for the papers' query")
    parser.add_argument("--general-seconds", type=float, default=5.0, help="stream length on the general path")
    parser.add_argument("--ros-trials", type=int, default=30)
    parser.add_argument("--measures", default="engine,rest,stream,ros", help="comma-separated subset")
    parser.add_argument("--write-docs", action="store_true", help="write the section into AFTER/docs/benchmarks.md")
    args = parser.parse_args()
    args.before, args.after = args.before.resolve(), args.after.resolve()
    args.measures = [m for m in args.measures.split(",") if m]
    unknown = [m for m in args.measures if m not in MEASURES]
    if unknown:
        parser.error(f"--measures: unknown {unknown}; choose from {sorted(MEASURES)}")
    for tree in (args.before, args.after):
        if not (tree / "gateway").is_dir():
            parser.error(f"{tree} is not a gateway tree (no gateway/ package)")
    if args.rounds % 2:
        parser.error("--rounds must be even, so both trees get as many rounds")
    return args


def main() -> None:
    args = parse()
    note = machine_note()
    print(note, flush=True)
    trees = {"before": args.before, "after": args.after}
    records: list[dict] = []
    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="compare-trees-") as tmp:
        n = 0
        while (not args.rounds or n < args.rounds) and (n % 2 or fits(records, start, args.budget)):
            side = ORDER[n % len(ORDER)]
            records.append(one_round(n + 1, side, trees[side], Path(tmp), args))
            print(json.dumps(records[-1], ensure_ascii=False), flush=True)
            n += 1
    args.rounds = n
    text = report(records, args, note)
    print(text)
    if args.write_docs:
        write_section(SECTION, text, args.after / "docs" / "benchmarks.md")


if __name__ == "__main__":
    main()
