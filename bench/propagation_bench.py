"""Deploy propagation across gateway processes: how long until a deploy made through one
`printeps serve` process is live on the others.

Three real `printeps serve` processes (no ROS) on one embedded MongoDB-protocol server (started
here, shared through MONGO_URI), each with the teahouse reception rule set (32 DSL rules). Each
round deploys a changed greeting through one process (round robin) and polls the other two with
fire requests every 5 ms until they answer with the new greeting. Propagation = first new answer
on a follower − the deploy's answer (the deploy is live on its own process when it answers).
Peers measured in the same run, for ratios: the deploy itself (compile + store, on the deploying
process) and a process restart (`printeps serve` until it answers), the other way to change rules.

    .venv/bin/python bench/propagation_bench.py [--rounds 20] [--write-docs]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from report import machine_note, write_section  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SECTION = "## Deploy propagation across processes"
FACTS = next(e["facts"] for e in json.loads((ROOT / "rules" / "drl" / "reception" / "examples.json").read_text())
             if e["name"] == "family with a baby")


def free_port() -> int:
    from gateway.serve import free_port as port

    return port()


def start(config: Path, env: dict[str, str], log: Path) -> tuple[subprocess.Popen, str]:
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "gateway.cli", "serve", "--no-ros", "--port", str(port),
                             "--config", str(config)], cwd=ROOT, env=env, stdout=open(log, "a"),
                            stderr=subprocess.STDOUT)
    return proc, f"http://127.0.0.1:{port}"


def ready(url: str, proc: subprocess.Popen, timeout: float = 300) -> float:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if proc.poll() is not None:
            raise RuntimeError(f"{url} exited")
        try:
            if httpx.get(f"{url}/api/rulesets/reception", timeout=2).status_code == 200:
                return time.monotonic() - t0
        except httpx.HTTPError:
            pass
        time.sleep(0.05)
    raise RuntimeError(f"{url} not ready")


def greeting(client: httpx.Client, url: str) -> str:
    """The first thing Pepper says to the example party."""
    answer = client.post(f"{url}/api/rulesets/reception/fire", json={"facts": FACTS}).json()
    return next(a["params"]["text"] for a in answer["actions"] if a["module"] == "say")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rounds", type=int, default=20)
    ap.add_argument("--write-docs", action="store_true")
    args = ap.parse_args()
    note = machine_note()
    from gateway.store.embedded import EmbeddedMongo

    with tempfile.TemporaryDirectory(prefix="bench-propagation-") as tmpdir:
        tmp = Path(tmpdir)
        db = EmbeddedMongo(tmp / "mongo")
        env = {**os.environ, "MONGO_URI": db.start()}
        config = tmp / "printeps.yaml"
        config.write_text(yaml.safe_dump({"data_dir": str(tmp / "var"), "streams": {"queries_dir": None}}))
        procs = []
        try:
            first, url = start(config, env, tmp / "p0.log")  # seeds the store first
            procs.append((first, url))
            ready(url, first)
            for i in (1, 2):
                procs.append(start(config, env, tmp / f"p{i}.log"))
            for proc, url in procs[1:]:
                ready(url, proc)
            urls = [u for _, u in procs]
            client = httpx.Client(timeout=30)
            original = client.get(f"{urls[0]}/api/rulesets/reception").json()["files"]
            anchor = greeting(client, urls[0])  # the sentence to change, as written in the .dslr
            assert anchor in original["reception.dslr"], anchor
            deploy_s, propagation_s = [], []
            for k in range(args.rounds + 2):
                new = f"Round {k} greeting."
                # the rules and their test scenarios (a red scenario would refuse the deploy)
                files = {name: text.replace(anchor, new) for name, text in original.items()}
                origin = urls[k % 3]
                followers = [u for u in urls if u != origin]
                seen: dict[str, float] = {}

                def poll(url: str) -> None:
                    c = httpx.Client(timeout=30)
                    deadline = time.monotonic() + 60
                    while time.monotonic() < deadline:
                        if greeting(c, url) == new:
                            seen[url] = time.perf_counter()
                            return
                        time.sleep(0.005)

                pollers = [threading.Thread(target=poll, args=(u,)) for u in followers]
                t0 = time.perf_counter()
                r = client.put(f"{origin}/api/rulesets/reception", json={"files": files, "comment": f"round {k}"})
                t1 = time.perf_counter()
                assert r.status_code == 201, r.text
                for p in pollers:
                    p.start()
                for p in pollers:
                    p.join()
                if k < 2:
                    continue  # warm-up rounds (JIT, caches)
                deploy_s.append(t1 - t0)
                propagation_s.extend(seen[u] - t1 for u in followers)
            client.close()
            # peer: a restart of one process, until it answers with the current rule set
            proc, url = procs[2]
            proc.terminate()
            proc.wait(timeout=60)
            proc, url = start(config, env, tmp / "p2-restart.log")
            procs[2] = (proc, url)
            restart_s = ready(url, proc)
        finally:
            for proc, _ in procs:
                proc.terminate()
            for proc, _ in procs:
                try:
                    proc.wait(timeout=60)
                except subprocess.TimeoutExpired:
                    proc.kill()
            db.stop()
    ordered = sorted(propagation_s)
    p50, worst = statistics.median(ordered), ordered[-1]
    p90 = ordered[min(len(ordered) - 1, int(0.9 * len(ordered)))]
    d50 = statistics.median(deploy_s)
    text = "\n".join([
        SECTION, "",
        f"`bench/propagation_bench.py`, {time.strftime('%Y-%m-%d %H:%M')} UTC, {note}: 3 `printeps serve` processes "
        f"on one embedded MongoDB-protocol server, the 32-rule reception set, {args.rounds} deploys round robin, "
        f"{len(ordered)} follower measurements (the other two processes polled every 5 ms).", "",
        "| measure | p50 | p90 | max | vs the deploy itself (p50) |",
        "|---|---|---|---|---|",
        f"| propagation: deploy answered → live on another process | {p50 * 1000:.0f} ms | {p90 * 1000:.0f} ms | "
        f"{worst * 1000:.0f} ms | {p50 / d50:.2f}x |",
        f"| peer: the deploy itself (compile + store, live on its own process) | {d50 * 1000:.0f} ms | "
        f"{sorted(deploy_s)[int(0.9 * (len(deploy_s) - 1))] * 1000:.0f} ms | {max(deploy_s) * 1000:.0f} ms | 1.00x |",
        f"| peer: restarting a process until it serves | {restart_s * 1000:.0f} ms | | | {restart_s / d50:.1f}x |",
        "",
        f"Goal p50 < 1 s: {p50 * 1000:.0f} ms ({'met' if p50 < 1 else 'NOT met'}). A follower learns of a deploy "
        "through the change stream of the catalog's change log at once; most of the propagation time is its "
        "own compilation of the new version, off its serving path (it answers with the old version until then).",
    ])
    print(text)
    if args.write_docs:
        write_section(SECTION, text)


if __name__ == "__main__":
    main()
