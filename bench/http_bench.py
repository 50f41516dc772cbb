"""HTTP benchmark of the REST gateway on loopback: recorded fires/s and p50/p99 for the 5-fact
teahouse request (the reception rule set's "family with a baby" example), with 1, 2 and 4 workers.

Runs the gateway as `printeps serve [--workers N]` in a subprocess (uvicorn + httptools + uvloop;
N worker processes on one port, each a full gateway member, sharing the embedded MongoDB-protocol
server the supervisor starts) and drives it with a minimal asyncio HTTP/1.1 keep-alive client (so
the client costs little of the 2 cores). Every fire is a recorded decision (in the Information
State) unless said otherwise. Peers measured in the same run, for ratios: fires not recorded, the
same decision via the KIE Server endpoint, `GET /api/whoami` (the HTTP floor of this stack:
routing + auth, no engine), and `engine.fire` in-process (no HTTP).

    .venv/bin/python bench/http_bench.py [--seconds 10] [--connections 8] [--workers 1,2,4] [--write-docs]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from report import machine_note, write_section  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RULES = ROOT / "rules" / "drl"
EXAMPLE = "family with a baby"
DOC = ROOT / "docs" / "benchmarks.md"
SECTION = "## REST gateway"
NOTES = ROOT / "bench" / "http_bench_notes.md"  # hand-written reading, kept with the generated section


def teahouse_facts() -> list[dict]:
    examples = json.loads((RULES / "reception" / "examples.json").read_text())
    facts = next(e["facts"] for e in examples if e["name"] == EXAMPLE)
    assert len(facts) == 5, len(facts)
    return facts


def kie_batch(facts: list[dict]) -> dict:
    commands = [{"insert": {"object": {f"org.printeps.reception.{f['type']}": {k: v for k, v in f.items() if k != "type"}}}}
                for f in facts]
    return {"lookup": None, "commands": [*commands, {"fire-all-rules": {"out-identifier": "fired"}}]}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


WARM_UP_S = 10.0
WARM_UP_LOAD_S = 5.0  # then the first run's requests, discarded: the JVM's JIT compiles the fire path under load


def start_server(tmp: Path, port: int, record_fires: bool = True, workers: int = 1, *,
                 settings: dict[str, dict[str, object]] | None = None, env: dict[str, str] | None = None,
                 launcher: list[str] | None = None, start_timeout_s: float = 300.0) -> subprocess.Popen:
    """`printeps serve --workers N` on ``port``; returns once every worker answers and warmed up.

    ``settings`` adds to the configuration's sections (e.g. ``{"jvm": {"extra_options": [...]}}``),
    ``env`` to the server's environment (e.g. ``MALLOC_ARENA_MAX``), and ``launcher`` replaces
    ``python -m gateway.cli`` (a wrapper that probes the process, see bench/memory_probe.py)."""
    tmp.mkdir(parents=True, exist_ok=True)
    config = tmp / "printeps.yaml"
    sections: dict[str, dict[str, object]] = {"engine": {"rules_dir": str(RULES)},
                                              "store": {"record_fires": record_fires}, "ros": {"enabled": False}}
    for section, values in (settings or {}).items():
        sections.setdefault(section, {}).update(values)
    config.write_text(yaml.safe_dump({"data_dir": str(tmp / "var"), **sections}))
    server_env = {k: v for k, v in os.environ.items() if k != "MONGO_URI"} | (env or {})
    # The server's log goes to a file: a pipe nobody drains fills at 64 KiB (the soak once stalled
    # on it before the gateway logged off its serving threads: gateway.base.logs)
    log_file = tmp / "server.log"
    with log_file.open("ab") as log_out:
        proc = subprocess.Popen(
            [*(launcher or [sys.executable, "-m", "gateway.cli"]), "serve", "--port", str(port), "--config", str(config),
             "--workers", str(workers)],
            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=log_out, env=server_env,
        )
    deadline = time.monotonic() + start_timeout_s
    seen: set[str] = set()
    while len(seen) < workers:  # each new connection may land on any worker: wait until all answered
        if proc.poll() is not None:
            raise RuntimeError(f"server exited: {log_file.read_text(errors='replace')[-2000:]}")
        if time.monotonic() > deadline:
            proc.kill()
            raise RuntimeError(f"only {len(seen)} of {workers} workers answered in {start_timeout_s:g} s")
        try:
            r = httpx.get(f"http://127.0.0.1:{port}/health", timeout=2)
            if r.status_code == 200:
                seen.add(r.json()["process"])
        except httpx.HTTPError:
            pass
        time.sleep(0.1)
    time.sleep(WARM_UP_S)  # let the start-up warm-up finish, as in a gateway in service
    return proc


def request_bytes(method: str, path: str, body: bytes | None) -> bytes:
    head = f"{method} {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: keep-alive\r\n"
    if body is not None:
        head += f"Content-Type: application/json\r\nContent-Length: {len(body)}\r\n"
    return head.encode() + b"\r\n" + (body or b"")


async def read_response(reader: asyncio.StreamReader) -> tuple[bytes, bytes]:
    """One HTTP/1.1 response off a keep-alive connection: its head and its body (Content-Length)."""
    head = await reader.readuntil(b"\r\n\r\n")
    length = 0
    for line in head.split(b"\r\n"):
        if line[:15].lower() == b"content-length:":
            length = int(line[15:])
    return head, await reader.readexactly(length)


async def one_connection(port: int, req: bytes, until: float, latencies: list[float], check: bytes) -> int:
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    errors = 0
    try:
        while time.perf_counter() < until:
            t0 = time.perf_counter()
            writer.write(req)
            head, body = await read_response(reader)
            latencies.append(time.perf_counter() - t0)
            if not head.startswith(b"HTTP/1.1 200") or check not in body:
                errors += 1
    finally:
        writer.close()
    return errors


async def drive(port: int, req: bytes, seconds: float, connections: int, check: bytes) -> dict:
    latencies: list[float] = []
    warm_until = time.perf_counter() + 3.0
    await one_connection(port, req, warm_until, [], check)  # warm-up (the JVM's JIT, caches)
    start = time.perf_counter()
    until = start + seconds
    errors = await asyncio.gather(*(one_connection(port, req, until, latencies, check) for _ in range(connections)))
    elapsed = time.perf_counter() - start
    return summarize(latencies, elapsed, sum(errors))


def summarize(latencies: list[float], elapsed: float, errors: int) -> dict:
    ordered = sorted(latencies)
    pick = lambda q: ordered[min(len(ordered) - 1, int(q * len(ordered)))] * 1000  # noqa: E731
    return {"requests": len(ordered), "errors": errors, "rps": len(ordered) / elapsed,
            "p50_ms": pick(0.50), "p99_ms": pick(0.99), "mean_ms": statistics.fmean(ordered) * 1000}


def in_process_fire(tmp: Path, facts: list[dict], seconds: float, warm_up_s: float = 3.0) -> dict:
    """engine.fire without HTTP, in a child process (its own JVM) so it does not share the server's;
    fired ``warm_up_s`` first, not counted (the JIT's compiles)."""
    code = (
        "import json,sys,time;from gateway.config import Settings;from gateway.engine import Engine\n"
        f"s=Settings.model_validate({{'data_dir': {str(tmp / 'inproc')!r}, 'engine': {{'rules_dir': {str(RULES)!r}}}}})\n"
        "e=Engine(s);e.seed(s.engine.rules_dir) if hasattr(e, 'seed') else e.seed_from();facts=json.loads(sys.argv[1]);secs=float(sys.argv[2])\n"
        f"end=time.perf_counter()+{float(warm_up_s)!r}\n"
        "while time.perf_counter()<end: e.fire('reception',facts)\n"
        "lat=[];t=time.perf_counter();end=t+secs\n"
        "while time.perf_counter()<end:\n"
        "    t0=time.perf_counter();e.fire('reception',facts);lat.append(time.perf_counter()-t0)\n"
        "print(json.dumps({'lat':lat,'elapsed':time.perf_counter()-t}))\n"
    )
    out = subprocess.run([sys.executable, "-c", code, json.dumps(facts), str(seconds)], cwd=ROOT,
                         capture_output=True, text=True, check=True).stdout
    data = json.loads(out.strip().splitlines()[-1])
    return summarize(data["lat"], data["elapsed"], 0)


def table(rows: dict[str, dict], base: str) -> str:
    lines = ["| request | connections | req/s | p50 ms | p99 ms | req/s vs REST fire | errors |",
             "|---|---|---|---|---|---|---|"]
    for name, r in rows.items():
        lines.append(f"| {name} | {r['connections']} | {r['rps']:.0f} | {r['p50_ms']:.2f} | {r['p99_ms']:.2f} "
                     f"| {r['rps'] / rows[base]['rps']:.2f}x | {r['errors']} |")
    return "\n".join(lines)


def measure(server_dir: Path, runs: list[tuple[str, bytes, int, bytes]], seconds: float, *, workers: int = 1,
            record_fires: bool = True) -> dict[str, dict]:
    """Start a gateway, drive each run against it, stop it."""
    port = free_port()
    server = start_server(server_dir, port, record_fires=record_fires, workers=workers)
    rows: dict[str, dict] = {}
    try:
        _, first_req, first_conns, first_check = runs[0]
        asyncio.run(drive(port, first_req, WARM_UP_LOAD_S, first_conns, first_check))
        for name, req, conns, check in runs:
            rows[name] = {**asyncio.run(drive(port, req, seconds, conns, check)), "connections": conns}
            print(name, json.dumps({k: round(v, 3) for k, v in rows[name].items()}), flush=True)
    finally:
        server.terminate()
        server.wait(timeout=60)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--connections", type=int, default=8, help="for the throughput runs")
    parser.add_argument("--workers", default="1,2,4", help="worker counts to measure recorded fires with")
    parser.add_argument("--write-docs", action="store_true", help=f"write the results into {DOC}")
    args = parser.parse_args()
    note = machine_note()
    facts = teahouse_facts()
    fire = request_bytes("POST", "/api/rulesets/reception/fire", json.dumps({"facts": facts}).encode())
    kie = request_bytes("POST", "/kie-server/services/rest/server/containers/instances/reception",
                        json.dumps(kie_batch(facts)).encode())
    floor = request_bytes("GET", "/api/whoami", None)
    conns = args.connections
    rows: dict[str, dict] = {}
    by_workers: dict[int, tuple[str, str]] = {}
    with tempfile.TemporaryDirectory() as tmpdir:
        tmp = Path(tmpdir)
        for n in (int(x) for x in args.workers.split(",")):
            through, latency = f"recorded REST fire, {n} worker(s)", f"recorded REST fire, {n} worker(s), 2 conns"
            runs = [(through, fire, conns, b'"decision_id"'), (latency, fire, 2, b'"decision_id"')]
            if n == 1:
                runs += [("recorded REST fire, 1 worker, 1 conn (latency)", fire, 1, b'"decision_id"'),
                         ("KIE Server batch, same facts, 1 worker", kie, conns, b'"SUCCESS"'),
                         ("GET /api/whoami (HTTP floor: auth, no engine), 1 worker", floor, conns, b'"role"')]
            rows.update(measure(tmp / f"w{n}", runs, args.seconds, workers=n))
            by_workers[n] = (through, latency)
        rows.update(measure(tmp / "no-record", [
            ("peer: REST fire not recorded, 1 worker", fire, conns, b'"actions"'),
            ("peer: REST fire not recorded, 1 worker, 2 conns", fire, 2, b'"actions"')],
            args.seconds, record_fires=False))
        rows["engine.fire in-process (no HTTP)"] = {**in_process_fire(tmp, facts, args.seconds), "connections": 1}
        print("in-process", json.dumps({k: round(v, 3) for k, v in rows["engine.fire in-process (no HTTP)"].items()}))

    base = by_workers[min(by_workers)][0]
    best_n = max(by_workers, key=lambda n: rows[by_workers[n][0]]["rps"])
    best = rows[by_workers[best_n][0]]
    best_latency = rows[by_workers[best_n][1]]
    lean = rows["peer: REST fire not recorded, 1 worker"]
    goals = [
        f"Goal >= 1,500 recorded fires/s on 2 cores: best {best['rps']:.0f}/s with {best_n} worker(s) at "
        f"{conns} connections ({'met' if best['rps'] >= 1500 else 'NOT met'}).",
        f"Goal p99 < 5 ms at 2 connections: {best_latency['p99_ms']:.2f} ms with {best_n} worker(s) "
        f"({'met' if best_latency['p99_ms'] < 5 else 'NOT met'}); "
        + "; ".join(f"{n} worker(s): {rows[lat]['p99_ms']:.2f} ms" for n, (_, lat) in sorted(by_workers.items())) + ".",
        f"Recording every decision costs {(1 - rows[base]['rps'] / lean['rps']) * 100:.0f}% of the single worker's "
        f"throughput ({rows[base]['rps']:.0f} vs {lean['rps']:.0f} req/s not recorded): the decision is journalled "
        "before the answer (one write() to the local journal), then shipped in batches to MongoDB, whose embedded "
        "server is a Python process on the same 2 cores.",
    ]
    text = "\n".join([
        SECTION,
        "",
        f"`bench/http_bench.py` ({args.seconds:.0f} s per run, {time.strftime('%Y-%m-%d %H:%M')} UTC, {note}; the "
        "load generator runs on the same cores): `POST /api/rulesets/reception/fire` with the 5-fact teahouse "
        f"request (\"{EXAMPLE}\"), `printeps serve --workers N` (uvicorn, httptools + uvloop), loopback, a minimal "
        "asyncio keep-alive client. Each server is first driven for "
        f"{WARM_UP_LOAD_S:.0f} s (not counted) so the JVM has compiled the fire path. Every fire is a recorded "
        "decision unless said otherwise.",
        "",
        table(rows, base),
        "",
        *goals,
        f"At {conns} connections the workers are saturated: latency there is mostly queueing, the req/s is the capacity.",
        *(["", NOTES.read_text().rstrip()] if NOTES.exists() else []),
    ])
    print("\n" + text)
    if args.write_docs:
        write_section(SECTION, text)


if __name__ == "__main__":
    main()
