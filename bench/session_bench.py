"""Stateful sessions: insert-and-fire over REST and over KIE (req/s, p99), a 1,000-call
conversation against one session, and a session's memory with 10,000 facts.

The gateway runs as `printeps serve` in a subprocess (its own JVM), driven on loopback by the
minimal asyncio keep-alive client of `http_bench.py`. Peers in the same run, for ratios: the
stateless REST fire and the stateless KIE batch of the same fact. The rule set is a small one
whose rules match each inserted fact on its own (so a session growing to tens of thousands of
facts does not change the work per call): what is measured is the session machinery (lookup,
lock, fact handles, the two-phase batch, the decision record), not rule complexity.

    .venv/bin/python bench/session_bench.py [--seconds 10] [--connections 4] [--write-docs]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import httpx
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from http_bench import drive, free_port, request_bytes, summarize
from report import machine_note, write_section

ROOT = Path(__file__).resolve().parent.parent
SECTION = "## Stateful sessions"
PKG = "org.printeps.bench"
RULES = {
    "visits.drl": f"""package {PKG};
import org.printeps.gateway.Actions;
global Actions actions;

declare Visit
    id : String
    party : int
end

rule "Greet"
when
    $v : Visit( party > 0 )
then
    actions.say("pepper", "Welcome");
end

rule "Big party"
when
    $v : Visit( party > 4 )
then
    actions.gesture("pepper", "bow");
end
"""}
FACT = {"type": "Visit", "id": "v", "party": 5}
KIE_FACT = {f"{PKG}.Visit": {"id": "v", "party": 5}}


def serve_visits(home: Path, port: int, sessions: dict) -> subprocess.Popen:
    """``printeps serve`` on ``home`` with the visits rule set and these ``sessions`` settings,
    once /health answers. The data dir is kept: a second call on the same ``home`` is a restart
    (bench/durable_sessions.py's takeover uses that)."""
    rules = home / "rules" / "visits"
    if not rules.exists():
        rules.mkdir(parents=True)
        for name, text in RULES.items():
            (rules / name).write_text(text)
    config = home / "printeps.yaml"
    config.write_text(yaml.safe_dump({
        "data_dir": str(home / "var"), "engine": {"rules_dir": str(home / "rules")}, "ros": {"enabled": False},
        "streams": {"queries_dir": None}, "sessions": sessions}))
    log_file = home / "server.log"  # not a pipe: one nobody drains fills at 64 KiB
    with log_file.open("ab") as log_out:
        proc = subprocess.Popen([sys.executable, "-m", "gateway.cli", "serve", "--port", str(port), "--config",
                                 str(config)], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=log_out)
    deadline = time.monotonic() + 300
    while True:
        if proc.poll() is not None:
            raise RuntimeError(log_file.read_text(errors="replace")[-2000:])
        try:
            if httpx.get(f"http://127.0.0.1:{port}/health", timeout=2).status_code == 200:
                return proc
        except httpx.HTTPError:
            pass
        if time.monotonic() > deadline:
            proc.kill()
            raise RuntimeError("the gateway did not start")
        time.sleep(0.2)


def start(tmp: Path, port: int) -> subprocess.Popen:
    tmp.mkdir(parents=True, exist_ok=True)
    proc = serve_visits(tmp, port, {"max_facts": 10_000_000, "max_per_ruleset": 1000})
    time.sleep(5)  # the start-up warm-up
    return proc


async def created(port: int, req: bytes, until: float, latencies: list[float], check: bytes) -> int:
    """http_bench.one_connection for a 201 answer (an insert, with its decision)."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    errors = 0
    try:
        while time.perf_counter() < until:
            t0 = time.perf_counter()
            writer.write(req)
            head = await reader.readuntil(b"\r\n\r\n")
            length = next(int(line[15:]) for line in head.split(b"\r\n") if line[:15].lower() == b"content-length:")
            body = await reader.readexactly(length)
            latencies.append(time.perf_counter() - t0)
            if not head.startswith(b"HTTP/1.1 201") or check not in body:
                errors += 1
    finally:
        writer.close()
    return errors


async def drive_each(port: int, reqs: list[bytes], seconds: float, check: bytes) -> dict:
    """One connection per request (each its own session), all at once."""
    latencies: list[float] = []
    warm = time.perf_counter() + 3.0
    await asyncio.gather(*(created(port, r, warm, [], check) for r in reqs))
    start_t = time.perf_counter()
    until = start_t + seconds
    errors = await asyncio.gather(*(created(port, r, until, latencies, check) for r in reqs))
    return summarize(latencies, time.perf_counter() - start_t, sum(errors))


def patient_post(c: httpx.Client, path: str, body: dict, deadline_s: float = 120.0) -> httpx.Response:
    """A POST as a well-behaved client makes it: a 503 or 429 refusal is sent again after its
    ``Retry-After`` (a durable session being rebuilt, a full queue); anything else is the answer."""
    deadline = time.monotonic() + deadline_s
    while True:
        r = c.post(path, json=body)
        if r.status_code not in (429, 503) or time.monotonic() > deadline:
            return r
        time.sleep(float(r.headers.get("retry-after", "1")))


def conversation(url: str, calls: int = 1000) -> dict:
    """``calls`` KIE calls against one session, as a client holding handles makes them: insert a
    visit (keeping its handle), modify it, fire, retract it — a quarter of the calls each."""
    per: dict[str, list[float]] = {"insert": [], "modify": [], "fire": [], "retract": []}
    path = "/kie-server/services/rest/server/containers/instances/visits"
    with httpx.Client(base_url=url, timeout=30) as c:
        start_t = time.perf_counter()
        for k in range(calls // 4):
            t0 = time.perf_counter()
            r = patient_post(c, path, {"lookup": "defaultKieSession", "commands": [
                {"insert": {"object": {f"{PKG}.Visit": {"id": f"c{k}", "party": 1}}, "out-identifier": "v",
                            "return-object": False}}]})
            assert r.status_code == 200, r.text
            handle = r.json()["result"]["execution-results"]["facts"][0]["value"]
            per["insert"].append(time.perf_counter() - t0)
            for kind, body in (("modify", {"modify": {"fact-handle": handle, "setters": [{"accessor": "party", "value": "6"}]}}),
                               ("fire", {"fire-all-rules": {"out-identifier": "n"}}),
                               ("retract", {"retract": {"fact-handle": handle}})):
                t0 = time.perf_counter()
                r = patient_post(c, path, {"lookup": "defaultKieSession", "commands": [body]})
                assert r.status_code == 200, r.text
                per[kind].append(time.perf_counter() - t0)
        elapsed = time.perf_counter() - start_t
        left = patient_post(c, path, {"lookup": "defaultKieSession", "commands": [{"get-fact-handles": {"out-identifier": "h"}}]})
        remaining = len(left.json()["result"]["execution-results"]["results"][0]["value"])
        patient_post(c, path, {"lookup": "defaultKieSession", "commands": [{"dispose": ""}]})
        stateless: list[float] = []
        for _ in range(calls):
            t0 = time.perf_counter()
            patient_post(c, "/api/rulesets/visits/fire", {"facts": [FACT]})
            stateless.append(time.perf_counter() - t0)
    all_calls = [x for v in per.values() for x in v]
    return {"elapsed": elapsed, "calls": len(all_calls), "remaining": remaining, "all": summarize(all_calls, elapsed, 0),
            "per": {k: summarize(v, sum(v), 0) for k, v in per.items()},
            "stateless": summarize(stateless, sum(stateless), 0)}


def memory() -> dict:
    """JVM heap held by one session with 10,000 facts (and 100,000), measured in a child process."""
    code = f"""
import json, gc
from gateway.config import Settings
from gateway.engine import Engine
from gateway.base import jvm
import jpype
e = Engine(Settings.model_validate({{"sessions": {{"max_facts": 1000000}}}}))
e.deploy("visits", {json.dumps(RULES)}, force=True)
System = jpype.JClass("java.lang.System"); Runtime = jpype.JClass("java.lang.Runtime").getRuntime()
def used():
    for _ in range(3): System.gc()
    return Runtime.totalMemory() - Runtime.freeMemory()
out = {{}}
for n in (10_000, 100_000):
    base = used()
    s = e.session_manager.open("visits", kind="rest")
    for k in range(0, n, 1000):
        s.execute([{{"op": "insert", "facts": [{{"type": "Visit", "id": f"v{{k+i}}", "party": 1}} for i in range(1000)]}},
                   {{"op": "fire", "max": -1}}])
    held = used() - base
    out[n] = {{"bytes": held, "per_fact": held / n, "facts": s.to_dict()["fact_count"]}}
    s.close()
print("MEM", json.dumps(out))
"""
    text = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return json.loads(next(line for line in text.splitlines() if line.startswith("MEM "))[4:])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--connections", type=int, default=4)
    parser.add_argument("--write-docs", action="store_true")
    args = parser.parse_args()
    note = machine_note()
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    rows: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as tmpdir:
        proc = start(Path(tmpdir), port)
        try:
            kie_path = "/kie-server/services/rest/server/containers/instances/visits"
            stateless_rest = request_bytes("POST", "/api/rulesets/visits/fire", json.dumps({"facts": [FACT]}).encode())
            stateless_kie = request_bytes("POST", kie_path, json.dumps({"commands": [
                {"insert": {"object": KIE_FACT}}, {"fire-all-rules": {"out-identifier": "n"}}]}).encode())
            stateful_kie = request_bytes("POST", kie_path, json.dumps({"lookup": "defaultKieSession", "commands": [
                {"insert": {"object": KIE_FACT}}, {"fire-all-rules": {"out-identifier": "n"}}]}).encode())
            sessions = [httpx.post(f"{url}/api/rulesets/visits/sessions", json={}).json()["id"]
                        for _ in range(args.connections)]
            stateful_rest = [request_bytes("POST", f"/api/rulesets/visits/sessions/{sid}/facts",
                                           json.dumps({"facts": [FACT], "fire": True}).encode()) for sid in sessions]
            for conns in (1, args.connections):
                rows[f"peer: stateless REST fire, {conns} conn"] = asyncio.run(
                    drive(port, stateless_rest, args.seconds, conns, b'"decision_id"'))
                rows[f"stateful REST insert+fire (a session per conn), {conns} conn"] = asyncio.run(
                    drive_each(port, stateful_rest[:conns], args.seconds, b'"decision_id"'))
                rows[f"peer: stateless KIE batch, {conns} conn"] = asyncio.run(
                    drive(port, stateless_kie, args.seconds, conns, b'"SUCCESS"'))
                rows[f"stateful KIE batch (lookup defaultKieSession), {conns} conn"] = asyncio.run(
                    drive(port, stateful_kie, args.seconds, conns, b'"SUCCESS"'))
                for name in list(rows)[-4:]:
                    print(name, json.dumps({k: round(v, 3) for k, v in rows[name].items()}), flush=True)
            held = {sid: httpx.get(f"{url}/api/rulesets/visits/sessions/{sid}").json()["fact_count"] for sid in sessions}
            named = httpx.get(f"{url}/api/rulesets/visits/sessions/defaultKieSession").json()["fact_count"]
            for sid in sessions:
                httpx.delete(f"{url}/api/rulesets/visits/sessions/{sid}")
            httpx.post(f"{url}{kie_path}", json={"lookup": "defaultKieSession", "commands": [{"dispose": ""}]})
            talk = conversation(url)
            print("conversation", json.dumps(talk)[:400], flush=True)
        finally:
            proc.terminate()
            proc.wait(timeout=60)
    mem = memory()
    print("memory", mem)
    lines = ["| request | connections | req/s | p50 ms | p99 ms | req/s vs its stateless peer | errors |",
             "|---|---|---|---|---|---|---|"]
    for name, r in rows.items():
        conns = name.rsplit(", ", 1)[1].split()[0]
        peer_name = ("peer: stateless REST fire" if "REST" in name else "peer: stateless KIE batch") + f", {conns} conn"
        lines.append(f"| {name} | {conns} | {r['rps']:.0f} | {r['p50_ms']:.2f} | {r['p99_ms']:.2f} | "
                     f"{r['rps'] / rows[peer_name]['rps']:.2f}x | {r['errors']} |")
    per = talk["per"]
    text = "\n".join([
        SECTION,
        "",
        f"`bench/session_bench.py` ({args.seconds:.0f} s per run, {time.strftime('%Y-%m-%d %H:%M')} UTC, {note}; "
        "the load generator runs on the same cores): `printeps serve` (1 process), loopback, one `Visit` fact per "
        "request and two rules that match it alone; every fire is a recorded decision. Stateful REST: "
        "`POST /api/rulesets/visits/sessions/{id}/facts` with `\"fire\": true` (one session per connection); stateful "
        "KIE: `insert` + `fire-all-rules` with `lookup: defaultKieSession` (all connections share that one session, "
        "as KIE clients of one ksession do). Peers in the same run: the stateless REST fire and the stateless KIE "
        "batch of the same fact.",
        "",
        "\n".join(lines),
        "",
        f"The sessions grew while measured (facts are kept): the REST sessions ended with "
        f"{', '.join(str(v) for v in held.values())} facts, the shared KIE session with {named}.",
        "",
        f"**A 1,000-call conversation against one session** (KIE, one connection, sequential: insert a visit and keep "
        f"its handle, modify it by handle, fire, retract it by handle — 250 rounds): {talk['calls']} calls in "
        f"{talk['elapsed']:.2f} s ({talk['calls'] / talk['elapsed']:.0f} calls/s), p50 {talk['all']['p50_ms']:.2f} ms, "
        f"p99 {talk['all']['p99_ms']:.2f} ms; by call: insert p99 {per['insert']['p99_ms']:.2f} ms, modify "
        f"{per['modify']['p99_ms']:.2f} ms, fire {per['fire']['p99_ms']:.2f} ms, retract {per['retract']['p99_ms']:.2f} ms; "
        f"{talk['remaining']} facts left at the end (every retract by handle landed). Peer, same connection: 1,000 "
        f"stateless REST fires, p50 {talk['stateless']['p50_ms']:.2f} ms, p99 {talk['stateless']['p99_ms']:.2f} ms "
        f"(a conversation call costs {talk['all']['p50_ms'] / talk['stateless']['p50_ms']:.2f}x a stateless fire at the median).",
        "",
        f"**Session memory** (JVM heap after full GCs, a session of this rule set, facts inserted in batches of 1,000 "
        f"and fired; child process): 10,000 facts hold {mem['10000']['bytes'] / 1e6:.1f} MB "
        f"({mem['10000']['per_fact']:.0f} bytes/fact: the fact, its Drools handle and network memory, and the handle "
        f"registry); 100,000 facts {mem['100000']['bytes'] / 1e6:.1f} MB ({mem['100000']['per_fact']:.0f} bytes/fact). "
        "The default heap (`jvm.max_heap` 768m) thus holds about a million such facts across all sessions; "
        "`sessions.max_facts` (100,000) bounds one session.",
    ])
    print("\n" + text)
    if args.write_docs:
        write_section(SECTION, text)


if __name__ == "__main__":
    main()
