"""``printeps demo``: the teahouse reception, end to end, on one machine.

A thin launcher of the one composition root: it builds the gateway exactly as ``printeps serve``
does (Information State, rules engine, knowledge, stream engine, ROS node, REST API + workbench),
then starts the two simulators as their own processes (a Pepper-like robot and a Kinect-like
entrance sensor replaying scenarios/teahouse-reception.yaml) and narrates what the gateway does,
from the gateway's own events. Headless: stops when the scenario is over. Otherwise the gateway
keeps running for the workbench until Ctrl-C.
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

from gateway.app import build_gateway
from gateway.config import PROJECT_ROOT, Settings, load_settings
from gateway.serve import free_port, serve_in_thread

log = logging.getLogger(__name__)

DEFAULT_SCENARIO = PROJECT_ROOT / "scenarios" / "teahouse-reception.yaml"
DEFAULT_TABLES = PROJECT_ROOT / "scenarios" / "teahouse-tables.yaml"


class Printer:
    """Timestamped, one-line narration of the demo (to stdout or any callable)."""

    def __init__(self, out: Callable[[str], None]) -> None:
        self.out = out
        self.t0 = time.monotonic()
        self._lock = threading.Lock()

    def __call__(self, text: str) -> None:
        with self._lock:
            self.out(f"[{time.monotonic() - self.t0:6.2f}s] {text}")


class Narrator:
    """Turns the gateway's events into the demo's lines and counts what happened."""

    def __init__(self, say: Printer) -> None:
        self.say = say
        self.detections = 0
        self.tables_left: list[str] = []

    def on_stream_event(self, event: dict[str, Any]) -> None:
        if event.get("kind") == "actions":
            people = [f.get("id") for f in event.get("facts", []) if f.get("type") == "Customer"]
            tables = [f.get("table") for f in event.get("facts", []) if f.get("type") == "TableLeft"]
            if people:
                self.detections += 1
                self.say(f"detected entering customers: {', '.join(str(p) for p in people)}")
            for table in tables:
                self.tables_left.append(str(table))
                self.say(f"the party at {table} has left (leaving-seat detection)")
            self.say(f"rules {event.get('ruleset')} v{event.get('version')} fired: "
                     f"{', '.join(f.get('rule', '?') for f in event.get('fired', []))} "
                     f"(decision {event.get('decision_id')})")
        elif event.get("kind") == "error":
            self.say(f"stream error: {event.get('error')}")

    def on_ros_event(self, kind: str, payload: dict[str, Any]) -> None:
        if kind == "rejected":
            self.say(f"rejected a sensor reading: {payload['error']}")

    def on_outcome(self, o: dict[str, Any]) -> None:
        p = o["action"].get("params", {})
        what = p.get("text") or p.get("location") or p.get("name") or ""
        who = p.get("robot") or ("gateway" if o["action"].get("module") == "workflow" else "?")
        self.say(f"  -> {who} {o['action'].get('module')} {what!r}: {o['status']}"
                 + ("" if o["status"] == "ok" else f" ({o['message']})"))


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


# Customers at table 1 ordering by voice (espeak-ng voices through the recogniser); the second one
# forgets the count and Pepper asks for it.
VOICE_CUSTOMERS = (
    ("en-us", ["two green teas please", "yes"]),
    ("en-us+f3", ["coffee please", "three", "yes"]),
)


def voice_orders(gateway: Any, say: Callable[[str], None], table: str = "table1") -> list[dict[str, Any]]:
    """Play :data:`VOICE_CUSTOMERS` at ``table``: each sentence is spoken by espeak-ng and goes
    through the recogniser and the dialogue rules like a customer's voice; returns the orders."""
    from gateway.dialogue.speech import SpeechUnavailable, synthesise

    orders: list[dict[str, Any]] = []
    for n, (voice, sentences) in enumerate(VOICE_CUSTOMERS, 1):
        for sentence in sentences:
            try:
                audio = synthesise(sentence, voice)
            except SpeechUnavailable as exc:
                say(f"voice orders skipped: {exc}")
                return orders
            answer = gateway.dialogue.turn(table, audio=audio, table=table)
            say(f"customer {n} at {table} says {sentence!r} -> heard {answer['heard']!r} ({answer['intent']}); "
                f"Pepper: {' '.join(answer['says'])}")
            if answer["state"] == "ordered":
                orders.append({"customer": n, "drink": answer["slots"]["drink"], "cups": answer["slots"]["cups"],
                               "decision_id": answer["decision_id"]})
                break
    return orders


def _read_calls(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    return [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]


def run_demo(settings: Settings | None = None, headless: bool = True, *, scenario: str | Path | None = None,
             tables: str | Path | None = None, speed: float = 1.0, domain_id: int | None = None,
             out: Callable[[str], None] = print, stop_event: threading.Event | None = None) -> dict[str, Any]:
    """Play the teahouse reception (entrance) and the tables (a party leaves, its table is
    cleared) end to end; returns the summary (also printed)."""
    from gateway.ros.runtime import ros_env_defaults
    from gateway.ros.scenario import TableScenario, load_scenario

    settings = settings or load_settings()
    say = Printer(out)
    narrator = Narrator(say)
    scenario_path = Path(scenario or DEFAULT_SCENARIO)
    plan = load_scenario(scenario_path)  # bad files fail here, before anything starts
    tables_path = Path(tables or DEFAULT_TABLES)
    table_plan = load_scenario(tables_path, TableScenario)
    ros_env_defaults()
    domain = domain_id if domain_id is not None else int(os.environ.get("ROS_DOMAIN_ID", "0"))
    work = Path(settings.data_dir) / "demo" / time.strftime("%Y%m%d-%H%M%S")
    work.mkdir(parents=True, exist_ok=True)
    calls_log = work / "robot_calls.jsonl"
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain)}
    stop_event = stop_event or threading.Event()
    started = time.monotonic()

    say(f"scenarios: {plan.name} ({plan.duration:.0f} s of entrance data) and {table_plan.name} "
        f"({table_plan.duration:.0f} s of table data), replay speed x{speed:g}; ROS_DOMAIN_ID={domain}")
    gateway = build_gateway(settings, rest=True, ros=True, domain_id=domain, on_ros_event=narrator.on_ros_event)
    server = robot = sensor = table_sensors = None
    try:
        health = gateway.store.health()
        say(f"Information State: {health['backend']} MongoDB at {health['uri']}")
        say("rules engine: " + ", ".join(f"{i.name} v{i.version}" for i in gateway.engine.live_versions()))
        gateway.streams.subscribe(narrator.on_stream_event)
        gateway.actions.add_listener(narrator.on_outcome)
        port = settings.api.port if not headless and _port_is_free(settings.api.port) else free_port()
        server, _ = serve_in_thread(gateway.app, port)
        url = f"http://127.0.0.1:{port}"
        say(f"REST API + workbench: {url}/  (decisions: {url}/api/decisions)")
        robot = _sim("gateway.ros.sim_robot", ["--name", "pepper", "--log", str(calls_log), "--speech-dir",
                                               str(work / "speech")], env, work / "robot.log")
        client = gateway.ros.caller.client("/pepper/speak", "printeps_interfaces/srv/Speak")
        if not client.wait_for_service(timeout_sec=30):
            raise RuntimeError(f"the robot simulator did not come up; see {work / 'robot.log'}")
        say("robot simulator (pepper) ready; starting the entrance sensor and the table sensors")
        sensor = _sim("gateway.ros.sim_sensor", [str(scenario_path), "--speed", str(speed)], env, work / "sensor.log")
        table_sensors = _sim("gateway.ros.sim_tables", [str(tables_path), "--speed", str(speed)], env,
                             work / "tables.log")
        deadline = time.monotonic() + max(plan.duration, table_plan.duration) / speed + 60
        while (sensor.poll() is None or table_sensors.poll() is None) and time.monotonic() < deadline \
                and not stop_event.is_set():
            time.sleep(0.1)
        say("customers at table 1 order by voice (espeak-ng through the speech recogniser and the dialogue rules)")
        orders = voice_orders(gateway, say)
        settle = time.monotonic() + 20  # let the last readings, robot calls and workflow runs finish

        while time.monotonic() < settle and not gateway.idle():
            time.sleep(0.05)
        time.sleep(0.5)
        stats = {**gateway.ros.stats, **gateway.actions.stats, "detections": narrator.detections,
                 "firings": narrator.detections, "tables_cleared": list(narrator.tables_left), "orders": orders}
        gateway.store.flush(timeout_s=10)
        say("scenario over")
        if not headless and not stop_event.is_set():
            say(f"gateway still running: open {url}/workbench to edit the rules; press Ctrl-C to stop")
            try:
                stop_event.wait()
            except KeyboardInterrupt:
                pass
    finally:
        _stop_proc(sensor)
        _stop_proc(table_sensors)
        _stop_proc(robot)
        if server:
            server.should_exit = True
        store_health = gateway.store.health() if gateway.store is not None else {}
        gateway.close()
    calls = _read_calls(calls_log)
    summary = {
        "scenario": plan.name, "tables_scenario": table_plan.name, "domain_id": domain, "duration_s": round(time.monotonic() - started, 1),
        **stats, "robot_calls": [{k: v for k, v in c.items() if k not in ("x", "y")} for c in calls],
        "greetings": [c["text"] for c in calls if c["service"] == "speak"],
        "store": store_health, "work_dir": str(work),
    }
    ordered = ", ".join(f"{o['cups']} x {o['drink']}" for o in stats["orders"]) or "none"
    out("")
    out("Summary")
    out(f"  sensor readings: {stats['readings']} (rejected {stats['rejected']}); parties detected: "
        f"{stats['detections']}; tables cleared: {', '.join(stats['tables_cleared']) or 'none'}; "
        f"actions: {stats['actions']} (failed {stats['failed']}); orders by voice: {ordered}")
    for c in calls:
        what = c.get("text") or c.get("location") or c.get("name")
        out(f"  pepper {c['service']:<8} {what}")
    out(f"  Information State: {store_health.get('status')} ({store_health.get('buffered')} buffered); logs in {work}")
    return summary
