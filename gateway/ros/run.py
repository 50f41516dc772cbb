"""Run the gateway ROS node as its own process: store + engine + node, until SIGINT/SIGTERM.

    python -m gateway.ros.run [--config printeps.yaml] [--ros-args -p ruleset:=reception ...]

Clean shutdown on SIGINT and SIGTERM: the worker finishes its reading, the executor is joined,
the node destroyed and the context shut down (so Fast DDS removes its /dev/shm files), the store
flushes (or keeps its spool on disk) and the embedded database is stopped.
"""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading

from gateway.config import load_settings


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    ros_args = argv[argv.index("--ros-args"):] if "--ros-args" in argv else []
    own = argv[: len(argv) - len(ros_args)]
    ap = argparse.ArgumentParser(description="PRINTEPS gateway ROS node")
    ap.add_argument("--config", default=None)
    args = ap.parse_args(own)
    sys.setswitchinterval(0.001)  # GIL hand-offs between executor/worker threads: see docs/ros.md
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    settings = load_settings(args.config)

    from gateway.ros.node import GatewayNode
    from gateway.ros.runtime import RosRuntime
    from gateway.ros.stages import engine_stage, pipeline_factory
    from gateway.store import open_store

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    store = open_store(settings)
    try:
        engine, rules = engine_stage(settings)
        rt = RosRuntime(args=["gateway", *ros_args])
        try:
            rt.make(GatewayNode, settings.ros, pipeline_factory(settings, store, rules), rules=rules, store=store)
            print("gateway node ready", flush=True)
            stop.wait()
            print("gateway node stopping", flush=True)
        finally:
            rt.shutdown()
    finally:
        store.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
