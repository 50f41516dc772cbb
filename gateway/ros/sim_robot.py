"""A Pepper-like robot as a real ROS node: serves <ns>/speak, <ns>/move_to, <ns>/gesture and logs them.

Why a simulator: the then-part must reach real ROS services in tests and in ``printeps demo``.
Each call is appended to ``calls`` (and to a JSONL log when given) with its arrival time, so tests
check what the robot was asked to do and in which order. ``hang_s`` makes it a robot that does not
answer in time (fault tests); ``fail`` makes every call return success=false. With ``speech_dir``
the robot really speaks: each ``speak`` is synthesised by espeak-ng into a WAV file there (its
path in the call's ``audio``), which the demo and the workbench can play.

    python -m gateway.ros.sim_robot --name pepper [--log calls.jsonl] [--hang-s 0] [--speech-dir DIR]
"""

from __future__ import annotations

import argparse
import json
import signal
import threading
import time
from pathlib import Path
from typing import Any, Callable

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from printeps_interfaces.srv import Gesture, MoveTo, Speak


class RobotSim(Node):
    def __init__(self, name: str = "pepper", *, log_path: str | Path | None = None, hang_s: float = 0.0,
                 fail: bool = False, on_call: Callable[[dict[str, Any]], None] | None = None,
                 context: Any = None, speech_dir: str | Path | None = None, voice: str = "en-us") -> None:
        super().__init__(f"{name}_sim", namespace=f"/{name}", context=context)
        self.robot = name
        self.hang_s = hang_s
        self.fail = fail
        self.position = "home"
        self.calls: list[dict[str, Any]] = []
        self.on_call = on_call
        self._log = open(log_path, "a", encoding="utf-8") if log_path else None
        self._lock = threading.Lock()
        self.speech_dir = Path(speech_dir) if speech_dir else None
        self.voice = voice
        group = ReentrantCallbackGroup()
        self.create_service(Speak, "speak", self._speak, callback_group=group)
        self.create_service(MoveTo, "move_to", self._move, callback_group=group)
        self.create_service(Gesture, "gesture", self._gesture, callback_group=group)

    def _note(self, kind: str, **fields: Any) -> None:
        entry = {"t": time.time(), "robot": self.robot, "service": kind, **fields}
        with self._lock:
            self.calls.append(entry)
            if self._log:
                self._log.write(json.dumps(entry) + "\n")
                self._log.flush()
        self.get_logger().info(f"{kind} {fields}")
        if self.on_call:
            self.on_call(entry)

    def _finish(self, res: Any, message: str) -> Any:
        if self.hang_s:
            time.sleep(self.hang_s)
        res.success = not self.fail
        res.message = "simulated failure" if self.fail else message
        return res

    def _speak(self, req: Speak.Request, res: Speak.Response) -> Speak.Response:
        self._note("speak", text=req.text, **self._voice(req.text))
        return self._finish(res, f"said: {req.text}")

    def _voice(self, text: str) -> dict[str, str]:
        """Speak ``text`` into a WAV file under ``speech_dir`` (nothing without one)."""
        if self.speech_dir is None:
            return {}
        from gateway.dialogue.speech import SpeechUnavailable, synthesise

        path = self.speech_dir / f"{time.time_ns()}-{self.robot}.wav"
        try:
            self.speech_dir.mkdir(parents=True, exist_ok=True)
            path.write_bytes(synthesise(text, self.voice))
        except (SpeechUnavailable, OSError) as exc:  # the robot still "says" it: the call is logged
            return {"audio_error": str(exc)}
        return {"audio": str(path)}

    def _move(self, req: MoveTo.Request, res: MoveTo.Response) -> MoveTo.Response:
        self._note("move_to", location=req.location, x=req.x, y=req.y)
        self.position = req.location or f"({req.x:.2f}, {req.y:.2f})"
        return self._finish(res, f"at {self.position}")

    def _gesture(self, req: Gesture.Request, res: Gesture.Response) -> Gesture.Response:
        self._note("gesture", name=req.name)
        return self._finish(res, f"did {req.name}")

    def destroy_node(self) -> None:
        if self._log:
            self._log.close()
            self._log = None
        super().destroy_node()


def main(argv: list[str] | None = None) -> int:
    from gateway.ros.runtime import RosRuntime

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--name", default="pepper")
    ap.add_argument("--log", default=None, help="append each call as a JSON line to this file")
    ap.add_argument("--hang-s", type=float, default=0.0)
    ap.add_argument("--fail", action="store_true")
    ap.add_argument("--speech-dir", default=None, help="speak each text with espeak-ng into a WAV file here")
    args = ap.parse_args(argv)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    rt = RosRuntime()
    try:
        rt.make(RobotSim, args.name, log_path=args.log, hang_s=args.hang_s, fail=args.fail,
                speech_dir=args.speech_dir)
        print(f"robot simulator {args.name} ready", flush=True)
        stop.wait()
    finally:
        rt.shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
