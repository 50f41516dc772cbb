"""Running a gateway: one process until a signal (:func:`run`), a background thread (demo, tests), or
N workers on one port. An entry point: it stands above the composition root it calls.

``printeps serve --workers N`` runs N worker processes listening on one port: each binds its own
socket with ``SO_REUSEPORT``, so the kernel spreads new connections evenly over the workers (one
shared socket, as in uvicorn's own multi-process mode, lets one busy process take most of them).
Each worker is a
full member of the gateway: it builds its own gateway through the one composition root
(:func:`gateway.app.build_gateway`), over the same Information State, so deploys and decisions are
shared and a change made through any worker is live in all of them. The parent only supervises:
it starts the embedded database once (when no ``MONGO_URI`` is set) so the workers can share it,
restarts a worker that dies, and stops everything on SIGINT/SIGTERM. The ROS node runs in worker 0
only (one node per gateway: a topic read by N workers would greet every party N times).
"""

from __future__ import annotations

import ipaddress
import logging
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from gateway.app import build_gateway
from gateway.base.logs import log_off_thread
from gateway.base.malloc import limit_arenas
from gateway.config import Settings, load_settings
from gateway.store.factory import embedded_database, store_uri

log = logging.getLogger(__name__)

RESTART_BACKOFF_S = (0.5, 1.0, 2.0, 5.0, 10.0)


def is_loopback(host: str) -> bool:
    """``host`` is reachable from this machine only (127.0.0.0/8, ::1, localhost)."""
    if host.strip().lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def open_mode_check(api: Any, host: str) -> tuple[str | None, str | None]:
    """``(refusal, warning)`` for listening on ``host`` with these API settings.

    Why: in open mode (no tokens) every caller is the developer ``anonymous``, who may deploy any
    DRL — and DRL is Java, so whoever reaches the port can run code on this machine. Open mode
    therefore stays on a loopback address: on any other address the gateway refuses to start
    unless ``PRINTEPS_API_OPEN=1`` (``api.open: true``) asks for it on purpose, and then it warns at
    every start."""
    if not api.is_open or is_loopback(host):
        return None, None
    if api.open:  # forced on purpose
        return None, (f"WARNING: the REST API is open (no authentication) on {host}, not only on this machine "
                      f"(PRINTEPS_API_OPEN=1): anyone who reaches it acts as the developer 'anonymous' and can run "
                      f"code on this host. Configure tokens (PRINTEPS_TOKENS) to stop this.")
    return (f"printeps: refusing to listen on {host} in open mode: no tokens are configured, so anyone who "
            f"reaches {host} could deploy rules, and rules are Java code that runs on this host.\n"
            f"  Configure tokens, e.g. PRINTEPS_TOKENS='<secret>:developer:alice,<secret2>:author:owner' "
            f"(or api.tokens in the config file; roles: developer, author, caller),\n"
            f"  or listen on this machine only (--host 127.0.0.1),\n"
            f"  or set PRINTEPS_API_OPEN=1 to run open on {host} on purpose (it warns at every start)."), None


def local_url(host: str, port: int) -> str:
    """The URL a process on this host reaches a server bound to ``host:port`` at."""
    if host in ("", "0.0.0.0", "::"):
        host = "127.0.0.1"
    return f"http://[{host}]:{port}" if ":" in host else f"http://{host}:{port}"


def serve(gateway: Any, host: str, port: int, *, sockets: list[socket.socket] | None = None,
          announce: str | None = None) -> None:
    """Serve ``gateway.app`` with uvicorn until SIGINT/SIGTERM (the caller closes the gateway).

    The process announces where other gateway processes reach it (``announce``, else
    ``host:port``; ``sessions.advertise_url`` wins): calls for the sessions it holds are
    forwarded there."""
    import gc

    import uvicorn

    gateway.announce(announce or local_url(host, port))
    gc.collect()
    gc.freeze()  # start-up objects (JPype, FastAPI, Drools proxies) leave the GC's scans: shorter pauses
    # uvicorn shuts down gracefully on SIGTERM, then raises the signal again for the handler it
    # found: make that an orderly exit, so the caller's ``gateway.close()`` runs (journal shipped,
    # ROS node destroyed, embedded database stopped) instead of the process dying on the spot.
    signal.signal(signal.SIGTERM, _exit_quietly)
    # log_config=None: uvicorn's loggers propagate to the process's queued handler (gateway.base.logs)
    # instead of writing to stderr themselves, under their own lock, in the serving threads
    config = uvicorn.Config(gateway.app, host=host, port=port, loop="auto", http="auto", log_level="info",
                            access_log=False, log_config=None)
    closing_server(config, on_exit=gateway.live.close).run(sockets=sockets)


def closing_server(config: Any, on_exit: Any) -> Any:
    """uvicorn's server that first calls ``on_exit`` (ends the gateway's open event streams) when
    told to stop: uvicorn waits for every response to finish, and a Live view's never does."""
    import uvicorn

    class ClosingServer(uvicorn.Server):
        def handle_exit(self, sig: int, frame: Any) -> None:
            try:
                on_exit()
            finally:
                super().handle_exit(sig, frame)

    return ClosingServer(config)


def _exit_quietly(signum: int, frame: Any) -> None:
    raise SystemExit(0)


def serve_in_thread(app: Any, port: int, name: str = "uvicorn", timeout_s: float = 30.0,
                    host: str = "127.0.0.1") -> tuple[Any, threading.Thread]:
    """Serve ``app`` on ``host:port`` in a daemon thread; returns once it accepts requests as
    ``(server, thread)`` (stop with ``server.should_exit = True``, then join)."""
    import uvicorn

    server = uvicorn.Server(uvicorn.Config(app, host=host, port=port, log_level="warning", lifespan="off"))
    gateway = getattr(app.state, "gateway", None)
    if gateway is not None:
        gateway.announce(local_url(host, port))
    thread = threading.Thread(target=server.run, name=name, daemon=True)
    thread.start()
    deadline = time.monotonic() + timeout_s
    while not server.started:
        if time.monotonic() > deadline or not thread.is_alive():
            server.should_exit = True
            raise RuntimeError(f"the gateway did not start on {host}:{port} within {timeout_s:.0f} s")
        time.sleep(0.05)
    return server, thread


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


# --------------------------------------------------------------------------- workers


def listening_socket(host: str, port: int, *, listen: bool = True) -> socket.socket:
    """A socket on ``host:port`` that other processes may bind too (``SO_REUSEPORT``)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEPORT, 1)
    sock.bind((host, port))
    if listen:
        sock.listen(2048)
    return sock


class Supervisor:
    """Starts, watches and restarts N worker processes over one socket (see the module docstring)."""

    def __init__(self, workers: int, host: str, port: int, *, config: str | None = None, ros: bool | None = None,
                 env: dict[str, str] | None = None) -> None:
        self.workers = workers
        self.host, self.port = host, port
        self.config = config
        self.ros = ros
        self.env = dict(os.environ if env is None else env)
        self.procs: list[subprocess.Popen[bytes] | None] = [None] * workers
        self.restarts = [0] * workers
        self._stop = threading.Event()
        self.embedded: Any = None

    def start_database(self, settings: Any) -> None:
        """The embedded database, once for all workers, unless a MongoDB URI is configured."""
        if store_uri(settings):
            return
        self.embedded = embedded_database(settings)
        self.env["MONGO_URI"] = self.embedded.start()
        print(f"embedded database at {self.env['MONGO_URI']} (shared by {self.workers} workers)", flush=True)

    def spawn(self, index: int) -> None:
        cmd = [sys.executable, "-m", "gateway.worker", "--index", str(index), "--host", self.host,
               "--port", str(self.port)]
        if self.config:
            cmd += ["--config", self.config]
        if self.ros is not None:
            cmd += ["--ros" if (self.ros and index == 0) else "--no-ros"]
        elif index != 0:
            cmd += ["--no-ros"]
        env = {**self.env, "PRINTEPS_WORKER_INDEX": str(index)}
        self.procs[index] = subprocess.Popen(cmd, env=env,
                                             preexec_fn=_die_with_parent if sys.platform == "linux" else None)

    def run(self, settings: Any) -> int:
        """Serve until SIGINT/SIGTERM; returns the exit code."""
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: self._stop.set())
        listening_socket(self.host, self.port, listen=False).close()  # the port is free: fail now, not in N workers
        try:
            self.start_database(settings)
            for index in range(self.workers):
                self.spawn(index)
            print(f"serving on http://{self.host}:{self.port} with {self.workers} workers", flush=True)
            while not self._stop.wait(0.5):
                self._watch()
        finally:
            self.shutdown()
        return 0

    def _watch(self) -> None:
        for index, proc in enumerate(self.procs):
            if proc is None or proc.poll() is None:
                continue
            pause = RESTART_BACKOFF_S[min(self.restarts[index], len(RESTART_BACKOFF_S) - 1)]
            log.error("worker %d (pid %d) exited with %s; restarting it in %.1f s", index, proc.pid, proc.returncode, pause)
            print(f"worker {index} (pid {proc.pid}) exited with {proc.returncode}; restarting", flush=True)
            self.restarts[index] += 1
            if self._stop.wait(pause):
                return
            self.spawn(index)

    def shutdown(self, timeout_s: float = 30.0) -> None:
        for proc in self.procs:
            if proc is not None and proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + timeout_s
        for proc in self.procs:
            if proc is None:
                continue
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
        if self.embedded is not None:
            self.embedded.stop()


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """Linux: a worker gets SIGTERM when the supervisor dies (no orphaned workers)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass


def worker_main(argv: list[str] | None = None) -> int:
    """One worker of ``printeps serve --workers N`` (``python -m gateway.worker``)."""
    import argparse

    ap = argparse.ArgumentParser(description="a PRINTEPS gateway worker (started by `printeps serve --workers`)")
    ap.add_argument("--index", type=int, default=0)
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=8080)
    ap.add_argument("--config", default=None)
    ap.add_argument("--ros", dest="ros", action="store_true", default=None)
    ap.add_argument("--no-ros", dest="ros", action="store_false")
    args = ap.parse_args(argv)
    sys.setswitchinterval(0.001)
    log_off_thread(fmt=f"%(asctime)s worker{args.index} %(levelname)s %(name)s: %(message)s")
    settings = load_settings(args.config)
    limit_arenas(settings.malloc_arena_max)  # before the JVM's and the servers' threads allocate
    gateway = build_gateway(settings, ros=args.ros)
    sock = listening_socket(args.host, args.port)  # after the build: a worker takes connections once it serves
    # A private loopback port of this worker alone: calls forwarded to the sessions it holds must
    # not land on the shared port, which may hand them to another worker.
    # With sessions.advertise_url (several hosts) it listens on the serving address instead, and
    # "{port}" in that URL names it.
    advertised = settings.sessions.advertise_url
    private_host = args.host if advertised else "127.0.0.1"
    private = socket.socket(socket.AF_INET6 if ":" in private_host else socket.AF_INET, socket.SOCK_STREAM)
    private.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    private.bind((private_host, 0))
    private.listen(256)
    private_port = private.getsockname()[1]
    try:
        serve(gateway, args.host, args.port, sockets=[sock, private],
              announce=advertised.replace("{port}", str(private_port)) if advertised else local_url("127.0.0.1", private_port))
    finally:
        gateway.close()
    return 0


def config_path(config: Path | None) -> str | None:
    return str(config) if config else os.environ.get("PRINTEPS_CONFIG")


def run(settings: Settings, *, rest: bool = True, ros: bool | None = None, host: str | None = None,
        port: int | None = None) -> None:
    """Build a gateway, run it until SIGINT/SIGTERM, shut it down (``printeps serve`` / ``printeps ros``).

    With ``rest`` uvicorn serves the app (and handles the signals); without, the process waits on
    the signals itself (the ROS launcher).
    """
    log_off_thread()  # no serving thread ever waits on a slow stderr
    limit_arenas(settings.malloc_arena_max)  # before the JVM's and the servers' threads allocate
    gateway = build_gateway(settings, rest=rest, ros=ros)
    try:
        if rest:
            serve(gateway, host or settings.api.host, port or settings.api.port)
            return
        stop = threading.Event()
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
        print("gateway node ready" if gateway.ros is not None else "gateway ready (no ROS node)", flush=True)
        stop.wait()
        print("gateway node stopping", flush=True)
    finally:
        gateway.close()
