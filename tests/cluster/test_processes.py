"""Several gateway processes over one real MongoDB-protocol server, as an operator runs them:
``printeps serve`` processes on their own ports (and ``--workers``), really started, stopped and
killed. One live rule base and one decision record across all of them."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections import Counter
from pathlib import Path

import httpx
import pytest
import yaml

from gateway.serve import free_port
from gw_testing import short_lived_jvm

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[2]

TYPES = """package org.printeps.cluster;
import org.printeps.gateway.Actions;
global Actions actions;
declare Customer
    id : String
    age : int
end
"""
RULES = """package org.printeps.cluster;
import org.printeps.gateway.Actions;
global Actions actions;
rule "Greet"
when
    $c : Customer()
then
    actions.say("pepper", "GREETING " + $c.getId());
end
"""
FACTS = [{"type": "Customer", "id": "c1", "age": 30}]


def files(greeting: str) -> dict[str, str]:
    return {"types.drl": TYPES, "rules.drl": RULES.replace("GREETING", greeting)}


class Process:
    """One ``printeps serve`` process (its output kept in a log file)."""

    def __init__(self, name: str, config: Path, env: dict[str, str], log_dir: Path, *extra: str) -> None:
        self.name = name
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log = log_dir / f"{name}.log"
        self.args = [sys.executable, "-m", "gateway.cli", "serve", "--port", str(self.port), "--no-ros",
                     "--config", str(config), *extra]
        self.env = env
        self.proc: subprocess.Popen | None = None

    def start(self) -> "Process":
        with open(self.log, "a") as out:
            self.proc = subprocess.Popen(self.args, env=self.env, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT)
        return self

    def ready(self, timeout: float = 180) -> "Process":
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            assert self.proc is not None and self.proc.poll() is None, self.output()
            try:
                if httpx.get(f"{self.url}/health", timeout=2).status_code == 200:
                    return self
            except httpx.HTTPError:
                pass
            time.sleep(0.2)
        raise AssertionError(f"{self.name} not ready in {timeout}s:\n{self.output()}")

    def output(self) -> str:
        return self.log.read_text(errors="replace")[-4000:] if self.log.exists() else ""

    def signal(self, sig: int) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(sig)
            self.proc.wait(timeout=60)

    def stop(self) -> None:
        self.terminate()
        self.wait_stopped()

    def terminate(self) -> None:
        """SIGTERM (a clean stop), not waited for."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)

    def wait_stopped(self) -> None:
        if self.proc is not None:
            try:
                self.proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                self.proc.kill()


def stop_all(*processes: Process) -> None:
    """Stop several processes at once: each clean stop takes 2-3 s (mostly waiting on its threads
    and the JVM), so one after the other left the test's worker idle that long per extra process."""
    for p in processes:
        p.terminate()
    for p in processes:
        p.wait_stopped()


def fire(url: str, greeting_of: dict | None = None) -> dict:
    r = httpx.post(f"{url}/api/rulesets/cluster/fire", json={"facts": FACTS}, timeout=10)
    assert r.status_code == 200, r.text
    return r.json()


def said(answer: dict) -> str:
    return answer["actions"][0]["params"]["text"]


def wait_for(cond, timeout: float = 10.0, step: float = 0.02) -> float | None:
    """Seconds until ``cond()`` held, or None if it never did within ``timeout``."""
    start = time.monotonic()
    while time.monotonic() - start < timeout:
        if cond():
            return time.monotonic() - start
        time.sleep(step)
    return None


def process_env(mongo_uri: str | None) -> dict[str, str]:
    """The environment of the ``printeps serve`` processes a cluster test starts: this one's, with
    ``MONGO_URI`` set to the test's server (or removed: the process starts its own), their JVM on C1
    only (:func:`gw_testing.short_lived_jvm`)."""
    env = {k: v for k, v in os.environ.items() if k != "MONGO_URI"}
    if mongo_uri is not None:
        env["MONGO_URI"] = mongo_uri
    return short_lived_jvm(env)


def cluster_home(tmp_path_factory, mongo, database: str, settings: dict) -> tuple[Path, Path, dict[str, str]]:
    """A host for gateway processes: a home with the ``cluster`` rule set ("Hello"), a
    printeps.yaml on one data dir and the test database ``database`` (plus ``settings``), and the
    environment that points them at the test's MongoDB-protocol server."""
    home = tmp_path_factory.mktemp(database)
    (home / "rules" / "cluster").mkdir(parents=True)
    for name, text in files("Hello").items():
        (home / "rules" / "cluster" / name).write_text(text)
    config = home / "printeps.yaml"
    config.write_text(yaml.safe_dump({
        "data_dir": str(home / "var"),
        "engine": {"rules_dir": str(home / "rules")},
        "store": {"database": database},
        "streams": {"queries_dir": None},
        **settings,
    }))
    return home, config, process_env(mongo.uri)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory, mongo):
    """Three gateway processes (A, B, C) on one database and one data dir (one host)."""
    home, config, env = cluster_home(tmp_path_factory, mongo, "cluster", {"sync": {"reconcile_interval_s": 5}})
    procs = {name: Process(name, config, env, home) for name in "ABC"}
    for p in procs.values():
        p.start()
    try:
        for p in procs.values():
            p.ready()
        yield procs
    finally:
        stop_all(*procs.values())


def deploy(url: str, greeting: str, base: int | None = None) -> httpx.Response:
    body: dict = {"files": files(greeting), "comment": greeting}
    if base is not None:
        body["base_version"] = base
    return httpx.put(f"{url}/api/rulesets/cluster", json=body, timeout=120)


def test_a_deploy_on_one_process_is_live_on_the_others(cluster):
    a, b, c = cluster["A"], cluster["B"], cluster["C"]
    assert said(fire(a.url)) == "Hello c1" == said(fire(b.url)) == said(fire(c.url))
    current = httpx.get(f"{a.url}/api/rulesets/cluster").json()["version"]
    r = deploy(a.url, "Welcome", base=current)
    assert r.status_code == 201, r.text
    for other in (b, c):
        assert wait_for(lambda: said(fire(other.url)) == "Welcome c1", 10) is not None, other.output()
    # base_version holds across processes: B's edit started from the old version
    stale = deploy(b.url, "Stale", base=current)
    assert stale.status_code == 409 and stale.json()["current"] == current + 1
    # a rollback on C is live on A
    assert httpx.post(f"{c.url}/api/rulesets/cluster/rollback", json={"version": current}).status_code == 200
    assert wait_for(lambda: said(fire(a.url)) == "Hello c1", 10) is not None
    history = httpx.get(f"{b.url}/api/rulesets/cluster/history").json()
    assert [h["event"] for h in history][-2:] == ["deploy", "rollback"]
    assert len({h["origin"] for h in history}) >= 2  # made by different processes


def test_a_decision_is_answered_by_any_process(cluster):
    a, b = cluster["A"], cluster["B"]
    answer = httpx.post(f"{b.url}/api/rulesets/cluster/fire", json={"facts": FACTS},
                        headers={"X-Request-ID": "from-b"}, timeout=10).json()
    found = wait_for(lambda: httpx.get(f"{a.url}/api/decisions/{answer['decision_id']}").status_code == 200, 10)
    assert found is not None
    decision = httpx.get(f"{a.url}/api/decisions/{answer['decision_id']}").json()
    assert decision["correlation_id"] == "from-b" and decision["origin"] == "rest"
    assert decision["process"].endswith(f":{cluster['B'].proc.pid}")


def test_the_live_view_of_one_process_shows_the_decisions_of_the_others(cluster):
    """The owner's Live feed on B shows what A decides (relayed through the Information State)."""
    a, b = cluster["A"], cluster["B"]
    seen: list[str] = []
    stop = threading.Event()

    def listen() -> None:
        with httpx.Client(timeout=30) as http, \
                http.stream("GET", f"{b.url}/api/live", params={"replay": "false", "heartbeat_s": 0.5}) as r:
            kind = None
            for line in r.iter_lines():
                if stop.is_set():
                    return
                if line.startswith("event: "):
                    kind = line[7:]
                elif line.startswith("data: ") and kind == "decision":
                    seen.append(json.loads(line[6:])["decision_id"])

    listener = threading.Thread(target=listen, daemon=True)
    listener.start()
    fired_on_a: list[str] = []
    try:
        def relayed() -> bool:
            fired_on_a.append(fire(a.url)["decision_id"])
            return bool(set(seen) & set(fired_on_a))
        assert wait_for(relayed, 20, step=0.3) is not None, b.output()
    finally:
        stop.set()


def test_a_restarted_process_serves_the_current_version_at_once(cluster):
    a, b = cluster["A"], cluster["B"]
    assert deploy(a.url, "Again").status_code == 201
    b.signal(signal.SIGTERM)
    assert b.proc.returncode == 0, b.output()
    b.start().ready()
    assert said(fire(b.url)) == "Again c1"  # the first request after the restart


def load(urls: list[str], stop: threading.Event, results: list[tuple[str, int, dict | str]]) -> None:
    """Fire round robin over ``urls`` until ``stop``; every answer (or failure) is recorded."""
    client = httpx.Client(timeout=10)
    i = 0
    while not stop.is_set():
        url = urls[i % len(urls)]
        i += 1
        try:
            r = client.post(f"{url}/api/rulesets/cluster/fire", json={"facts": FACTS})
            results.append((url, r.status_code, r.json() if r.status_code == 200 else r.text))
        except httpx.HTTPError as exc:
            results.append((url, -1, repr(exc)))
    client.close()


def test_deploys_during_load_fail_no_fire(cluster):
    a, b, c = cluster["A"], cluster["B"], cluster["C"]
    stop, results = threading.Event(), []
    workers = [threading.Thread(target=load, args=([p.url for p in (a, b, c)], stop, results)) for _ in range(4)]
    for w in workers:
        w.start()
    try:
        deployed = [deploy([a, b, c][k % 3].url, f"Round{k}").json()["version"] for k in range(10)]
        # the load goes on past the last deploy: a dozen more fires answered (or failed) after it
        after = len(results)
        assert wait_for(lambda: len(results) >= after + 12, 60) is not None, "the load stopped after the deploys"
    finally:
        stop.set()
        for w in workers:
            w.join(timeout=30)
    failures = [r for r in results if r[1] != 200]
    assert results and not failures, failures[:5]
    versions = {r[2]["version"] for r in results}
    assert versions & set(deployed)  # fires were answered by the new versions while they came in


def test_sigkill_under_load_fails_nothing_on_the_others_and_loses_no_acknowledged_decision(cluster, mongo):
    a, b, c = cluster["A"], cluster["B"], cluster["C"]
    stop, results = threading.Event(), []
    workers = [threading.Thread(target=load, args=([p.url for p in (a, b, c)], stop, results)) for _ in range(4)]
    for w in workers:
        w.start()

    def answered(urls: set[str], since: int, each: int) -> bool:
        counts = {u: 0 for u in urls}
        for url, status, _ in results[since:]:
            if url in counts and status == 200:
                counts[url] += 1
        return all(n >= each for n in counts.values())

    try:
        # every process is under load and answering before C dies...
        assert wait_for(lambda: answered({a.url, b.url, c.url}, 0, 5), 60) is not None, results[-5:]
        c.signal(signal.SIGKILL)
        killed_at = len(results)
        # ...and the others go on answering after it (C's calls fail meanwhile)
        assert wait_for(lambda: answered({a.url, b.url}, killed_at, 10)
                        and any(r[0] == c.url and r[1] != 200 for r in results[killed_at:]), 60) is not None, results[-5:]
    finally:
        stop.set()
    for w in workers:
        w.join(timeout=30)
    others = [r for r in results if r[0] != c.url]
    assert others and all(r[1] == 200 for r in others), [r for r in others if r[1] != 200][:5]
    acknowledged = [r[2]["decision_id"] for r in results if r[1] == 200]
    from_c = [r[2]["decision_id"] for r in results if r[0] == c.url and r[1] == 200]
    assert from_c, "C answered nothing before it was killed"
    # C's journal is adopted by A or B (same host, same data dir) and shipped: nothing acknowledged is lost
    missing = acknowledged

    def all_found() -> bool:
        nonlocal missing
        missing = [d for d in missing if httpx.get(f"{a.url}/api/decisions/{d}", timeout=5).status_code != 200]
        return not missing

    # within 2 minutes: a database overloaded by the load is retried with a backoff of up to 8 s
    assert wait_for(all_found, 120, step=1.0) is not None, lost_report(missing, results, cluster, mongo)
    c.start().ready()  # back for the module's other tests


def lost_report(missing: list[str], results: list, cluster: dict, mongo) -> str:
    """Why acknowledged decisions are not found: who answered them, what each live process's store
    says (journal backlog, last error), what is left in the journal folder, the database's log."""
    answered_by = {r[2]["decision_id"]: r[0] for r in results if r[1] == 200}
    names = {p.url: name for name, p in cluster.items()}
    by_process = Counter(names.get(answered_by.get(d, ""), "?") for d in missing)
    lines = [f"{len(missing)} acknowledged decisions missing, answered by {dict(by_process)}; e.g. {missing[:3]}"]
    for name, p in cluster.items():
        if p.proc is not None and p.proc.poll() is None:
            try:
                lines.append(f"{name} /health: {httpx.get(f'{p.url}/health', timeout=10).text}")
            except httpx.HTTPError as exc:
                lines.append(f"{name} /health: {exc!r}")
        lines.append(f"{name} output:\n{p.output()}")
    journal = Path(cluster["A"].args[cluster["A"].args.index("--config") + 1]).parent / "var" / "store" / "journal"
    left = ", ".join(f"{f.name} ({f.stat().st_size} B)" for f in sorted(journal.glob("*")))
    lines.append(f"journal {journal}: {left or 'empty'}")
    db_log = mongo.data_dir / "secantusd.log"
    lines.append("database log (tail): " + (db_log.read_text(errors="replace")[-3000:] if db_log.exists() else "none"))
    return "\n".join(lines)


def test_workers_share_one_port_and_one_rule_base(tmp_path, mongo):
    """``printeps serve --workers 2``: two full members behind one port."""
    home = tmp_path
    (home / "rules" / "cluster").mkdir(parents=True)
    for name, text in files("Hi").items():
        (home / "rules" / "cluster" / name).write_text(text)
    config = home / "printeps.yaml"
    config.write_text(yaml.safe_dump({"data_dir": str(home / "var"), "engine": {"rules_dir": str(home / "rules")},
                                      "store": {"database": "workers"}, "streams": {"queries_dir": None}}))
    env = process_env(mongo.uri)
    supervisor = Process("workers", config, env, home, "--workers", "2").start()
    try:
        supervisor.ready()
        assert said(fire(supervisor.url)) == "Hi c1"
        assert deploy(supervisor.url, "Bonjour").status_code == 201
        client = httpx.Client(timeout=10)
        # every worker serves the new version (each request on a new connection: either worker)
        assert wait_for(lambda: all(said(fire(supervisor.url)) == "Bonjour c1" for _ in range(10)), 10) is not None
        answers = [fire(supervisor.url) for _ in range(40)]
        processes = set()
        for answer in answers:
            decision = None
            for _ in range(50):
                r = client.get(f"{supervisor.url}/api/decisions/{answer['decision_id']}")
                if r.status_code == 200:
                    decision = r.json()
                    break
                time.sleep(0.1)
            assert decision is not None
            processes.add(decision["process"])
        assert len(processes) == 2, processes  # both workers answered
        client.close()
    finally:
        supervisor.stop()
    assert supervisor.proc.returncode == 0, supervisor.output()


def test_a_second_gateway_on_a_held_data_dir_says_who_holds_it(tmp_path):
    home = tmp_path
    config = home / "printeps.yaml"
    config.write_text(yaml.safe_dump({"data_dir": str(home / "var"), "engine": {"rules_dir": str(home / "none")},
                                      "streams": {"queries_dir": None}}))
    env = process_env(None)
    first = Process("first", config, env, home).start()
    try:
        first.ready()
        second = subprocess.run([sys.executable, "-m", "gateway.cli", "serve", "--port", str(free_port()), "--no-ros",
                                 "--config", str(config)], env=env, cwd=ROOT, capture_output=True, text=True,
                                timeout=120)
    finally:
        first.stop()
    assert second.returncode == 3, second.stdout + second.stderr
    message = second.stderr
    assert f"held by process {first.proc.pid}" in message and "MONGO_URI='mongodb://127.0.0.1:" in message
    assert "Traceback" not in message
