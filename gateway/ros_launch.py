"""The ROS launcher as a module: ``python -m gateway.ros_launch`` = ``printeps ros``.

There is no ``ros2 launch`` here (no ``launch`` wheels on PyPI): this is the launch-equivalent. It
builds the gateway through the one composition root (:func:`gateway.serve.run`) with the ROS node on
and no HTTP, and runs it until SIGINT/SIGTERM — the ingress finishes its message, the executor is
joined, the node destroyed and the context shut down (so Fast DDS removes its /dev/shm files), the
Information State ships its journal (or keeps it on disk) and the embedded database is stopped.

    python -m gateway.ros_launch [--config printeps.yaml]
"""

from __future__ import annotations

import argparse
import sys

from gateway.config import load_settings
from gateway.serve import run


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="PRINTEPS gateway ROS node (the same gateway as `printeps serve`, no HTTP)")
    ap.add_argument("--config", default=None)
    args, ros_args = ap.parse_known_args(sys.argv[1:] if argv is None else argv)
    settings = load_settings(args.config)
    settings.ros.args = ros_args  # --ros-args -p name:=value ... reach the node (start-up overrides)
    sys.setswitchinterval(0.001)  # GIL hand-offs between executor and worker threads: see docs/ros.md
    run(settings, rest=False, ros=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
