"""Run ``gateway.cli`` with a memory probe inside it: glibc's malloc totals and, optionally,
Python's own allocations (tracemalloc), written every ``PROBE_EVERY_S`` seconds.

Why a wrapper: the gateway's slow native rise (docs/benchmarks.md "Soak") is outside what the JVM
and ``/health`` report, and what glibc holds (in use against free but kept: fragmentation) or what
Python allocated (by source line) can only be read from inside the process. bench/soak.py
``--probe`` starts the server through this file instead of ``python -m gateway.cli``; the product
never imports it.

Environment:
- ``PROBE_DIR`` (required): the probe starts once a file ``start`` appears there; where ``probe.jsonl`` (one line per tick) and, with tracemalloc,
  ``tracemalloc_top.txt`` (the allocation sites that grew most since the first tick) go;
- ``PROBE_EVERY_S`` (default 60);
- ``PROBE_MALLOC_TRIM=1``: call ``malloc_trim(0)`` at every tick, after the malloc totals (what
  the RSS gives back is what glibc held free);
- ``PROBE_TYPES=1``: also count the collector's objects by type at every tick (types_top.txt:
  the types that grew most since the first tick);
- ``PROBE_TRACEMALLOC`` (frames, default 0: off). Tracing costs CPU and memory of its own (the
  trace table is reported apart, ``tracemalloc_overhead_mb``).
"""

from __future__ import annotations

import ctypes
import gc
import json
import os
import runpy
import sys
import threading
import time
import tracemalloc
from collections import Counter
from pathlib import Path


class MallInfo2(ctypes.Structure):
    """glibc's ``struct mallinfo2`` (glibc >= 2.33): totals over every malloc arena."""

    _fields_ = [(name, ctypes.c_size_t) for name in (
        "arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks", "keepcost")]


def malloc_totals() -> dict[str, float]:
    """MB in use (``uordblks`` + mmapped chunks), free but kept by the arenas (``fordblks``: what
    fragmentation holds) and the arenas' size (``arena``), or {} without glibc's mallinfo2."""
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallinfo2.restype = MallInfo2
    except (OSError, AttributeError):
        return {}
    info = libc.mallinfo2()
    mb = 2 ** 20
    return {"malloc_in_use_mb": round((info.uordblks + info.hblkhd) / mb, 1),
            "malloc_free_kept_mb": round(info.fordblks / mb, 1), "malloc_arena_mb": round(info.arena / mb, 1),
            "malloc_mmapped_mb": round(info.hblkhd / mb, 1)}


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return round(int(line.split()[1]) / 1024, 1)
    return 0.0


def trim() -> dict[str, float]:
    """``malloc_trim(0)``: glibc gives the free pages of every arena back to the system; the RSS
    before and after says how much of the process was memory malloc held free (fragmentation)."""
    before = rss_mb()
    started = time.perf_counter()
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    return {"rss_before_trim_mb": before, "rss_after_trim_mb": rss_mb(),
            "trim_ms": round((time.perf_counter() - started) * 1000, 1)}


def threads() -> int:
    return len(os.listdir("/proc/self/task"))


def type_counts() -> Counter[str]:
    """Objects the collector tracks, by type (``module.qualname``): what a steady rise of
    ``python_objects`` is made of."""
    return Counter(f"{type(o).__module__}.{type(o).__qualname__}" for o in gc.get_objects())


def write_type_growth(out: Path, t_min: float, first: list[Counter[str]]) -> None:
    counts = type_counts()
    if not first:
        first.append(counts)
        return
    grown = sorted(((n - first[0].get(name, 0), name) for name, n in counts.items()), reverse=True)[:30]
    (out / "types_top.txt").write_text(f"t={t_min} min, objects by type, change since the first tick:\n"
                                       + "".join(f"{d:+8d}  {name}\n" for d, name in grown))


def tick(out: Path, started: float, first: list[tracemalloc.Snapshot]) -> None:
    row: dict[str, object] = {"t_min": round((time.monotonic() - started) / 60, 2), "threads": threads(),
                              "python_objects": len(gc.get_objects()), **malloc_totals()}
    if os.environ.get("PROBE_MALLOC_TRIM") == "1":
        row.update(trim())
    if os.environ.get("PROBE_TYPES") == "1":
        write_type_growth(out, row["t_min"], FIRST_TYPES)  # type: ignore[arg-type]
    if tracemalloc.is_tracing():
        snap = tracemalloc.take_snapshot().filter_traces([tracemalloc.Filter(False, tracemalloc.__file__)])
        row["python_traced_mb"] = round(tracemalloc.get_traced_memory()[0] / 2 ** 20, 1)
        row["tracemalloc_overhead_mb"] = round(tracemalloc.get_tracemalloc_memory() / 2 ** 20, 1)
        if not first:
            first.append(snap)
        else:
            stats = snap.compare_to(first[0], "lineno")[:40]
            text = [f"t={row['t_min']} min, since t={first[0].t_min} min (KB, count):"]  # type: ignore[attr-defined]
            text += [f"{s.size_diff / 1024:+10.1f} KB {s.count_diff:+8d}  {s.traceback}" for s in stats]
            (out / "tracemalloc_top.txt").write_text("\n".join(text) + "\n")
        setattr(snap, "t_min", row["t_min"])
    with (out / "probe.jsonl").open("a") as fh:
        fh.write(json.dumps(row) + "\n")


FIRST_TYPES: list[Counter[str]] = []


def run_probe(out: Path, every: float, frames: int) -> None:
    """Waits for ``out/start`` (bench/soak.py writes it once the gateway is warm), then starts
    tracing (with ``frames``) and ticks every ``every`` s: what is traced is only what was allocated
    since the gateway was warm and is still alive, and the start-up (imports, the first builds)
    runs untraced, at full speed."""
    while not (out / "start").exists():
        time.sleep(1.0)
    if frames:
        tracemalloc.start(frames)
    started, first = time.monotonic(), []
    while True:
        try:
            tick(out, started, first)
        except Exception as exc:  # noqa: BLE001 - a probe must not take the gateway down
            print(f"memory probe: {exc!r}", file=sys.stderr)
        time.sleep(every)


def main() -> None:
    out = Path(os.environ["PROBE_DIR"])
    out.mkdir(parents=True, exist_ok=True)
    frames = int(os.environ.get("PROBE_TRACEMALLOC", "0"))
    threading.Thread(target=run_probe, args=(out, float(os.environ.get("PROBE_EVERY_S", "60")), frames),
                     name="memory-probe", daemon=True).start()
    sys.argv = ["gateway.cli", *sys.argv[1:]]
    runpy.run_module("gateway.cli", run_name="__main__", alter_sys=True)


if __name__ == "__main__":
    main()
