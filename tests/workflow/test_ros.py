"""Real ROS 2: generated workflow nodes run as their own processes against the Pepper simulator
(and the gateway's ROS node for "fire business rules"); the executor's rclpy adapter calls robots."""

from __future__ import annotations

import itertools
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gw_testing import short_lived_jvm, wait_for

pytest.importorskip("rclpy", reason="ROS 2 wheels not installed (ros/install.sh)")
pytest.importorskip("printeps_interfaces", reason="printeps_interfaces not built (ros/install.sh)")

from gateway.config import PROJECT_ROOT  # noqa: E402
from gateway.workflow.codegen import generate  # noqa: E402
from gateway.workflow.loader import load  # noqa: E402

pytestmark = pytest.mark.ros
_domains = itertools.count(140 + os.getpid() % 50)


@pytest.fixture
def ros_env() -> dict[str, str]:
    """Each test on its own ROS domain, discovery on loopback only."""
    env = dict(os.environ, ROS_DOMAIN_ID=str(1 + next(_domains) % 100), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    return env


class Proc:
    """A child process stopped with SIGINT (so Fast DDS cleans up), killed only if it hangs."""

    def __init__(self, args: list[str], env: dict[str, str], log: Path) -> None:
        self.log = log
        self.handle = subprocess.Popen(args, env=env, stdout=open(log, "w"), stderr=subprocess.STDOUT,
                                       cwd=PROJECT_ROOT)

    def wait_for(self, text: str, timeout: float = 60) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if text in self.log.read_text(errors="replace"):
                return
            if self.handle.poll() is not None:
                raise AssertionError(f"process ended: {self.log.read_text()[-2000:]}")
            time.sleep(0.05)
        raise AssertionError(f"{text!r} not seen in {timeout}s: {self.log.read_text()[-2000:]}")

    def stop(self) -> None:
        if self.handle.poll() is None:
            self.handle.send_signal(signal.SIGINT)
            try:
                self.handle.wait(timeout=15)
            except subprocess.TimeoutExpired:
                self.handle.kill()
                self.handle.wait(timeout=5)


@pytest.fixture
def pepper(ros_env, tmp_path):
    calls = tmp_path / "pepper.jsonl"
    proc = Proc([sys.executable, "-m", "gateway.ros.sim_robot", "--name", "pepper", "--log", str(calls)],
                ros_env, tmp_path / "pepper.log")
    proc.wait_for("robot simulator pepper ready")
    yield calls
    proc.stop()


def robot_calls(log: Path) -> list[tuple]:
    if not log.exists():
        return []
    out = []
    for line in log.read_text().splitlines():
        entry = json.loads(line)
        out.append((entry["service"], entry.get("text") or entry.get("name") or entry.get("location")
                    or (round(entry["x"], 2), round(entry["y"], 2))))
    return out


def run_generated(path: Path, ros_env: dict[str, str], tmp_path: Path, *args: str, timeout: float = 90) -> dict:
    source = tmp_path / f"{path.stem}_node.py"
    source.write_text(generate(load(path), version=1))
    done = subprocess.run([sys.executable, str(source), *args], env=ros_env, capture_output=True, text=True,
                          timeout=timeout, cwd=tmp_path)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    assert lines, done.stdout[-2000:] + done.stderr[-3000:]
    return json.loads(lines[-1])


def test_generated_node_runs_the_thanking_workflow(pepper, ros_env, tmp_path):
    result = run_generated(PROJECT_ROOT / "workflows" / "7_thanking.yaml", ros_env, tmp_path, "--timeout", "20")
    assert result["status"] == "succeeded", result
    assert robot_calls(pepper) == [("move_to", "entrance"), ("speak", "Thank you very much. Please come again."),
                                   ("gesture", "bow"), ("move_to", "counter")]


def test_generated_node_passes_data_and_values(pepper, ros_env, tmp_path):
    result = run_generated(PROJECT_ROOT / "workflows" / "2_show_to_seat.yaml", ros_env, tmp_path,
                           "--timeout", "20", "--values", '{"pepper1.robotToHumanDistance": 0.8, "pepper1.robotToTableDistance": 0.5}',
                           "--inputs", '{"party": {"size": 2, "x": 2.0, "y": 1.0}}')
    assert result["status"] == "succeeded", result
    assert robot_calls(pepper) == [("move_to", (2.8, 1.0)), ("move_to", (3.5, 2.0))]


def test_generated_node_reports_a_missing_robot_as_a_failed_step(ros_env, tmp_path):
    result = run_generated(PROJECT_ROOT / "workflows" / "7_thanking.yaml", ros_env, tmp_path, "--timeout", "0.5")
    assert result["status"] == "failed" and "not available" in result["error"]
    assert result["steps"][0]["step_id"] == "go_to_door"


def test_generated_greeting_fires_rules_in_the_gateway_node(pepper, ros_env, tmp_path):
    env = dict(ros_env, PRINTEPS_DATA_DIR=str(tmp_path / "var"))
    gateway = Proc([sys.executable, "-m", "gateway.ros_launch"], short_lived_jvm(env), tmp_path / "gateway.log")
    try:
        result = run_generated(PROJECT_ROOT / "workflows" / "1_greeting.yaml", env, tmp_path, "--timeout", "60",
                               timeout=150)
    finally:
        gateway.stop()
    assert result["status"] == "succeeded", result
    said = [value for service, value in robot_calls(pepper) if service == "speak"]
    assert "Welcome. Two seats?" in said
    dispatched = [s for s in result["steps"] if s.get("via") == "reception_rules"]
    assert dispatched and all(s["status"] == "ok" for s in dispatched)


def test_workflows_call_robots_through_the_gateway_node(pepper, ros_env, tmp_path, mongo):
    """A gateway built with its ROS node runs workflows against real robot services through that
    node (one ROS context per gateway), with ontology values from its knowledge base."""
    from gateway.config import Settings
    from gw_testing import built_gateway

    settings = Settings.model_validate({"data_dir": str(tmp_path / "var"), "workflows": {"simulate_robots": False},
                                        "ros": {"domain_id": int(ros_env["ROS_DOMAIN_ID"])}})
    with built_gateway(settings, mongo, tmp_path, ros=True) as gateway:
        result = gateway.workflows.run("take_order")
        assert result.status == "succeeded", result.error
        # Pepper's side of the dialogue goes through the action router (as every rule action does),
        # the workflow's own steps through the workflow: both reach the robot over ROS
        dialogue = [("speak", "What would you like to drink?"), ("speak", "2 green teas, certainly. Is that right?"),
                    ("speak", "Thank you. Your green teas will be ready soon.")]
        assert wait_for(lambda: all(c in robot_calls(pepper) for c in dialogue), 20), robot_calls(pepper)
        calls = robot_calls(pepper)
        assert [c for c in calls if c in dialogue] == dialogue
        assert [c for c in calls if c not in dialogue] == [
            ("move_to", (3.5, 2.0)),  # 4.0 - pepper1.robotToTableDistance 0.5
            ("speak", "2 green teas, certainly. I will bring them to your table.")]
        assert result.steps[-1].output == {"published": "/teahouse/kitchen"}
