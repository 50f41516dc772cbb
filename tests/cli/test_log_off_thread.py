"""Logging never holds up a thread that logs, even when nobody reads the process's stderr."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

PROJECT = Path(__file__).resolve().parents[2]

CHILD = textwrap.dedent("""
    import logging, sys, threading, time
    from gateway.base.logs import log_off_thread
    writer = log_off_thread(max_records=100)
    log = logging.getLogger("lane")

    def lane():  # a fire lane that logs a failure per decision, as the action router did in the soak
        for i in range(5000):
            log.error("action %d failed: %s", i, "x" * 100)

    t = threading.Thread(target=lane)
    t.start()
    t.join(30)
    print("done" if not t.is_alive() else "stuck", flush=True)
    sys.stdin.readline()  # the parent reads stderr from now on
    while not writer.records.empty():
        time.sleep(0.01)
    log.warning("last")  # caught up: records flow again, and the exit writes what is queued
""")


def test_a_thread_that_logs_never_waits_on_an_unread_stderr() -> None:
    """5,000 errors (~600 KB) into a stderr pipe nobody reads (64 KB): with the handler writing in
    the logging thread, the lane blocked with the logging lock held (and every other thread that
    logged behind it). Queued, the lane finishes; what did not fit is dropped, and said so."""
    child = subprocess.Popen([sys.executable, "-c", CHILD], cwd=PROJECT, stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "done"
        _, err = child.communicate("go\n", timeout=60)
    finally:
        child.kill()
    assert child.returncode == 0, err[-2000:]
    assert "log records dropped: stderr was not read fast enough" in err
    assert err.rstrip().endswith("lane: last")


DEMO_CHILD = textwrap.dedent("""
    import logging
    import gateway.demo
    from gateway.cli import app

    def fake_run_demo(settings, **options):  # what the demo's threads log through, at its start
        root = logging.getLogger()
        print("handlers", [type(h).__name__ for h in root.handlers], logging.getLevelName(root.level), flush=True)
        return {}

    gateway.demo.run_demo = fake_run_demo
    app(["demo", "--headless"], standalone_mode=False)
""")


def test_printeps_demo_logs_through_the_queue_as_serve_does(tmp_path: Path) -> None:
    """`make run` is `printeps demo`: its gateway threads (stream engine, action router, ROS node)
    log through the bounded queue too, showing warnings and errors as before."""
    done = subprocess.run([sys.executable, "-c", DEMO_CHILD], cwd=PROJECT, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PRINTEPS_DATA_DIR": str(tmp_path)})
    assert done.returncode == 0, done.stderr[-2000:]
    assert "handlers ['DroppingQueueHandler'] WARNING" in done.stdout
