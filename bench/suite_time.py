"""Where the test suite's time goes: wall time and CPU time (user+sys) of a pytest run's whole
process tree, per run and per test.

Why: on a shared or loaded machine wall time says little, and the suite's cost is spread over
processes pytest starts (SecantusDB, ``printeps serve`` gateways, chromium, node). The CPU time of
the tree says how much of two cores a part of the suite needs; wall minus CPU/cores is what it
spends waiting (idle), which a second pytest worker could overlap.

    python bench/suite_time.py --out /tmp/engine.json -- tests/engine -q

runs pytest as a child under a child subreaper (so orphaned grandchildren are reaped here and
their CPU counted), prints the tree's wall/user/sys, and writes per-test rows (wall, CPU of pytest
and its live descendants) to ``--out``. The per-test CPU misses processes that exit without their
parent waiting for them; the run's total does not.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

PR_SET_CHILD_SUBREAPER = 36
CLOCK_TICKS = os.sysconf("SC_CLK_TCK")


# ---- the pytest plugin (loaded in the child with -p suite_time) -------------------------------

def _proc_table() -> dict[int, tuple[int, float]]:
    """``{pid: (ppid, user+sys+waited-for children's user+sys in seconds)}`` from /proc."""
    table: dict[int, tuple[int, float]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            raw = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        fields = raw[raw.rindex(")") + 2:].split()
        ticks = sum(int(value) for value in fields[11:15])  # utime stime cutime cstime
        table[int(entry)] = (int(fields[1]), ticks / CLOCK_TICKS)
    return table


def tree_cpu(root: int | None = None) -> float:
    """CPU seconds of ``root`` (this process by default) and every live descendant, each with the
    children it has waited for."""
    root = root or os.getpid()
    table = _proc_table()
    children: dict[int, list[int]] = {}
    for pid, (ppid, _) in table.items():
        children.setdefault(ppid, []).append(pid)
    total, todo = 0.0, [root]
    while todo:
        pid = todo.pop()
        total += table.get(pid, (0, 0.0))[1]
        todo.extend(children.get(pid, ()))
    return total


_rows: list[dict[str, object]] = []


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item, nextitem):  # noqa: ANN001, ANN201 - pytest hook
    """Times one test (setup, call, teardown) in wall and tree CPU seconds."""
    wall, cpu = time.monotonic(), tree_cpu()
    result = yield
    row = {"nodeid": item.nodeid, "wall": round(time.monotonic() - wall, 3), "cpu": round(tree_cpu() - cpu, 3)}
    _rows.append(row)
    out = os.environ.get("SUITE_TIME_OUT")
    if out:  # one line a test as it ends, so a run cut short still says where its time went
        with open(f"{out}.rows", "a", encoding="utf-8") as rows:
            rows.write(json.dumps(row) + "\n")
    return result


def pytest_sessionfinish(session, exitstatus):  # noqa: ANN001, ANN201 - pytest hook
    out = os.environ.get("SUITE_TIME_OUT")
    if out:
        Path(out).write_text(json.dumps({"tests": _rows, "cpu_at_end": tree_cpu()}, indent=1))


# ---- the runner --------------------------------------------------------------------------------

def run(pytest_args: list[str], out: Path | None) -> int:
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [env.get("PYTHONPATH"), str(Path(__file__).parent)]))
    if out:
        env["SUITE_TIME_OUT"] = str(out)
    started = time.monotonic()
    child = subprocess.Popen([sys.executable, "-m", "pytest", "-p", "suite_time", *pytest_args], env=env)
    status = child.wait()
    pytest_done = time.monotonic() - started
    while True:  # the orphans that outlived pytest were re-parented here: wait for them too
        try:
            os.wait()
        except ChildProcessError:
            break
    used = os.times()
    wall = time.monotonic() - started
    cpu = used.children_user + used.children_system
    summary = {"args": pytest_args, "exit": status, "wall": round(wall, 1), "pytest_wall": round(pytest_done, 1),
               "user": round(used.children_user, 1), "sys": round(used.children_system, 1), "cpu": round(cpu, 1),
               "load_at_end": os.getloadavg()[0]}
    print("suite_time:", json.dumps(summary), flush=True)
    if out:
        data = json.loads(out.read_text()) if out.exists() else {}
        out.write_text(json.dumps({**data, "summary": summary}, indent=1))
    return status


def load_rows(path: Path) -> list[dict[str, object]]:
    """The per-test rows of a run: its JSON file, or the ``.rows`` lines of a run cut short."""
    if path.suffix == ".rows":
        return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return json.loads(path.read_text())["tests"]


def report(paths: list[Path], top: int) -> None:
    """Per test file: tests, wall and CPU seconds, and CPU/wall (cores used), biggest CPU first."""
    files: dict[str, list[float]] = {}
    for path in paths:
        if path.suffix == ".json" and "summary" in (data := json.loads(path.read_text())):
            print(f"{path}: the run's whole tree: {data['summary']['cpu']} s CPU, {data['summary']['wall']} s wall")
        for row in load_rows(path):
            if float(row["cpu"]) < 0:  # type: ignore[arg-type]
                # a tree that ended outside pytest's waits (a session fixture's teardown, reaped by
                # the runner): its CPU is in the run's total, not in any test's
                continue
            name = str(row["nodeid"]).split("::", 1)[0]
            totals = files.setdefault(name, [0, 0.0, 0.0])
            totals[0] += 1
            totals[1] += float(row["wall"])  # type: ignore[arg-type]
            totals[2] += float(row["cpu"])  # type: ignore[arg-type]
    print(f"{'file':60} {'tests':>5} {'wall s':>8} {'cpu s':>8} {'cores':>5}")
    for name, (count, wall, cpu) in sorted(files.items(), key=lambda item: -item[1][2])[:top]:
        print(f"{name:60} {count:5d} {wall:8.1f} {cpu:8.1f} {cpu / wall if wall else 0:5.2f}")
    count, wall, cpu = (sum(values[i] for values in files.values()) for i in range(3))
    print(f"{'all':60} {int(count):5d} {wall:8.1f} {cpu:8.1f} {cpu / wall if wall else 0:5.2f}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, help="JSON file for the per-test rows and the summary")
    parser.add_argument("--report", type=Path, nargs="+", help="print the per-file table of these runs instead")
    parser.add_argument("--top", type=int, default=40, help="how many files --report lists")
    parser.add_argument("pytest_args", nargs=argparse.REMAINDER, help="after --: pytest's arguments")
    args = parser.parse_args()
    if args.report:
        report(args.report, args.top)
        return 0
    pytest_args = args.pytest_args[1:] if args.pytest_args[:1] == ["--"] else args.pytest_args
    return run(pytest_args, args.out)


if __name__ == "__main__":
    sys.exit(main())
