"""``printeps demo``: the teahouse reception, end to end, on one machine.

Starts the embedded database (or uses MONGO_URI), the rules engine, the REST API + workbench
(uvicorn on 127.0.0.1), the gateway ROS node, and the two simulators as their own processes (a
Pepper-like robot and a Kinect-like entrance sensor replaying scenarios/teahouse-reception.yaml).
Prints what happens as it happens and returns a summary. Headless: stops when the scenario is over.
Otherwise it opens the workbench and keeps running until Ctrl-C.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable

from gateway.config import PROJECT_ROOT, Settings, load_settings

log = logging.getLogger(__name__)

DEFAULT_SCENARIO = PROJECT_ROOT / "scenarios" / "teahouse-reception.yaml"


class Printer:
    """Timestamped, one-line narration of the demo (to stdout or any callable)."""

    def __init__(self, out: Callable[[str], None]) -> None:
        self.out = out
        self.t0 = time.monotonic()
        self._lock = threading.Lock()

    def __call__(self, text: str) -> None:
        with self._lock:
            self.out(f"[{time.monotonic() - self.t0:6.2f}s] {text}")


def _start_rest(settings: Settings, engine: Any, store: Any, ros_check: Callable[[], dict], say: Printer,
                headless: bool = True):
    """The REST API + workbench on loopback: the configured port (8080) when it is free and the
    demo is interactive, else any free port. (None, None) when the API package is not there."""
    try:
        from gateway.server import build_app, serve_in_thread
    except ImportError as exc:
        say(f"REST API not available ({exc}); continuing without it")
        return None, None
    from gateway.store.embedded import free_port

    app, _ = build_app(settings, engine, store, health_checks={"ros": ros_check})
    port = settings.api.port if not headless and _port_is_free(settings.api.port) else free_port()
    server, _ = serve_in_thread(app, port)
    return server, f"http://127.0.0.1:{port}"


def _port_is_free(port: int) -> bool:
    import socket

    with socket.socket() as sock:
        try:
            sock.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _sim(module: str, args: list[str], env: dict[str, str], logfile: Path) -> subprocess.Popen:
    out = open(logfile, "w", encoding="utf-8")
    proc = subprocess.Popen([sys.executable, "-m", module, *args], env=env, cwd=PROJECT_ROOT, stdout=out,
                            stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    out.close()
    return proc


def _stop_proc(proc: subprocess.Popen | None, timeout_s: float = 10.0) -> None:
    """SIGINT first (ROS cleans its /dev/shm files), SIGKILL only as a last resort."""
    if proc is None or proc.poll() is not None:
        return
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()


def _read_calls(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]


def run_demo(settings: Settings | None = None, headless: bool = True, *, scenario: str | Path | None = None,
             speed: float = 1.0, domain_id: int | None = None, out: Callable[[str], None] = print,
             stop_event: threading.Event | None = None) -> dict[str, Any]:
    """Play the teahouse reception end to end; returns the summary (also printed)."""
    from gateway.ros.node import GatewayNode
    from gateway.ros.runtime import RosRuntime, ros_env_defaults
    from gateway.ros.scenario import load_scenario
    from gateway.ros.stages import engine_stage, pipeline_factory
    from gateway.store import open_store

    settings = settings or load_settings()
    say = Printer(out)
    scenario_path = Path(scenario or DEFAULT_SCENARIO)
    plan = load_scenario(scenario_path)  # bad files fail here, before anything starts
    ros_env_defaults()
    domain = domain_id if domain_id is not None else int(os.environ.get("ROS_DOMAIN_ID", "0"))
    work = Path(settings.data_dir) / "demo" / time.strftime("%Y%m%d-%H%M%S")
    work.mkdir(parents=True, exist_ok=True)
    calls_log = work / "robot_calls.jsonl"
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    stop_event = stop_event or threading.Event()
    started = time.monotonic()

    say(f"scenario: {plan.name} ({plan.duration:.0f} s of sensor data, replay speed x{speed:g}); "
        f"ROS_DOMAIN_ID={domain}")
    store = open_store(settings)
    say(f"Information State: {store.health()['backend']} MongoDB at {store.health()['uri']}")
    rt = server = robot = sensor = None
    try:
        engine, rules = engine_stage(settings)
        say("rules engine: " + ", ".join(f"{i.name} v{i.version}" for i in engine.list_rulesets()))
        rt = RosRuntime(domain_id=domain)

        def ros_check() -> dict[str, Any]:
            return {"status": "ok", "domain_id": domain, "node": settings.ros.node_name}

        server, url = _start_rest(settings, engine, store, ros_check, say, headless)
        if url:
            say(f"REST API + workbench: {url}/  (Information State: {url}/api/state/actions)")

        def on_event(kind: str, payload: dict[str, Any]) -> None:
            if kind == "detected":
                say(f"detected entering customers: {', '.join(payload['customers'])}")
            elif kind == "fired":
                say(f"rules {payload['ruleset']} v{payload['version']} fired: {', '.join(payload['rules'])}")
            elif kind == "rejected":
                say(f"rejected a sensor reading: {payload['error']}")

        def on_outcome(o: dict[str, Any]) -> None:
            p = o["action"].get("params", {})
            what = p.get("text") or p.get("location") or p.get("name") or ""
            say(f"  -> {p.get('robot', '?')} {o['action'].get('module')} {what!r}: {o['status']}"
                + ("" if o["status"] == "ok" else f" ({o['message']})"))

        node = rt.make(GatewayNode, settings.ros, pipeline_factory(settings, store, rules, on_event=on_event,
                                                                   on_outcome=on_outcome),
                       rules=rules, store=store)
        robot = _sim("gateway.ros.sim_robot", ["--name", "pepper", "--log", str(calls_log)], env, work / "robot.log")
        client = node.caller.client("/pepper/speak", "Speak")
        if not client.wait_for_service(timeout_sec=30):
            raise RuntimeError(f"the robot simulator did not come up; see {work / 'robot.log'}")
        say("robot simulator (pepper) ready; starting the entrance sensor")
        sensor = _sim("gateway.ros.sim_sensor", [str(scenario_path), "--speed", str(speed)], env, work / "sensor.log")
        deadline = time.monotonic() + plan.duration / speed + 60
        while sensor.poll() is None and time.monotonic() < deadline and not stop_event.is_set():
            time.sleep(0.1)
        # let the last readings and robot calls finish
        settle = time.monotonic() + 15
        while time.monotonic() < settle and not node.queue.empty():
            time.sleep(0.05)
        time.sleep(0.5)
        stats = dict(node.pipeline.stats)
        say("scenario over")
        if not headless and url and not stop_event.is_set():
            say(f"gateway still running: open {url}/workbench to edit the rules; press Ctrl-C to stop")
            try:
                stop_event.wait()
            except KeyboardInterrupt:
                pass
    finally:
        _stop_proc(sensor)
        _stop_proc(robot)
        if rt:
            rt.shutdown()
        if server:
            server.should_exit = True
            writer = getattr(server.config.app.state, "store_writer", None)
            if writer is not None:
                writer.close()  # queued Information State records are written before the store closes
        health = store.health()
        store.close()
    calls = _read_calls(calls_log)
    summary = {
        "scenario": plan.name, "domain_id": domain, "duration_s": round(time.monotonic() - started, 1),
        **stats, "robot_calls": [{k: v for k, v in c.items() if k not in ("x", "y")} for c in calls],
        "greetings": [c["text"] for c in calls if c["service"] == "speak"],
        "store": health, "work_dir": str(work),
    }
    out("")
    out("Summary")
    out(f"  sensor readings: {stats['readings']} (rejected {stats['rejected']}); detections: {stats['detections']}; "
        f"rule firings: {stats['firings']}; robot actions: {stats['actions']} (failed {stats['failed']})")
    for c in calls:
        what = c.get("text") or c.get("location") or c.get("name")
        out(f"  pepper {c['service']:<8} {what}")
    out(f"  Information State: {health['status']} ({health['buffered']} buffered); logs in {work}")
    return summary


def main(argv: list[str] | None = None) -> int:
    """``python -m gateway.demo [--headless] [--speed N] [--scenario FILE]`` (the CLI wraps this)."""
    import argparse

    ap = argparse.ArgumentParser(description="PRINTEPS teahouse reception demo")
    ap.add_argument("--headless", action="store_true")
    ap.add_argument("--speed", type=float, default=1.0)
    ap.add_argument("--scenario", default=None)
    ap.add_argument("--config", default=None)
    args = ap.parse_args(argv)
    sys.setswitchinterval(0.001)  # GIL hand-offs between executor/worker threads: see docs/ros.md
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    summary = run_demo(load_settings(args.config), headless=args.headless, scenario=args.scenario,
                       speed=args.speed, stop_event=stop)
    return 0 if summary["greetings"] else 1


if __name__ == "__main__":
    raise SystemExit(main())
