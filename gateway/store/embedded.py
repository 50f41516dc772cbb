"""The embedded development database: SecantusDB run as its own process, reached only via pymongo.

Why a subprocess: SecantusDB is GPL-2.0, so the gateway never imports it; it runs its CLI daemon on a
free loopback port with its data under the gateway's data dir, exactly as a real mongod would, so the
store's pymongo code path is the same for the embedded and a real MongoDB. It is started as a
single-node replica set (no ``--standalone``), which is what gives the gateway change streams.

One process owns a data dir's database: it holds an exclusive lock on ``<dir>/owner.lock`` and
writes ``<dir>/owner.json`` (its pid, command and the database URI). A second process that tries
to start the same database gets :class:`EmbeddedDbHeld`, which says who holds it and how to join
the running gateway instead (``MONGO_URI``); tools such as ``printeps export`` join it directly.
"""

from __future__ import annotations

import fcntl
import json
import logging
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pymongo

log = logging.getLogger(__name__)

DAEMON = "secantusd-py"


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """Linux: SIGINT the daemon if the gateway dies without stopping it (no orphaned databases)."""
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGINT)  # PR_SET_PDEATHSIG
    except OSError:
        pass


class EmbeddedDbError(RuntimeError):
    """The embedded database could not be started (not installed, crashed, never answered)."""


class EmbeddedDbHeld(EmbeddedDbError):
    """Another live process runs the embedded database of this data dir."""

    def __init__(self, data_dir: Path, owner: dict) -> None:
        self.owner = owner
        command = " ".join(owner.get("command") or []) or "?"
        uri = owner.get("uri") or "?"
        super().__init__(
            f"the embedded database in {data_dir} is held by process {owner.get('pid', '?')} ({command}), "
            f"serving at {uri}. To join that running gateway, start this process with "
            f"MONGO_URI='{uri}' (and its own data dir: PRINTEPS_DATA_DIR), or stop process "
            f"{owner.get('pid', '?')} first.")


def _wait_for_previous_daemon(data_dir: Path, timeout_s: float) -> None:
    """Wait (up to ``timeout_s``) until the database daemon of this data dir's previous owner is gone.

    Why: an owner killed with SIGKILL drops its lock at once, but its daemon only then gets SIGINT
    (PR_SET_PDEATHSIG) and shuts down with the storage still open; a new daemon started meanwhile
    exits with code 1 (a lone restart right after a SIGKILL, seen in bench/durable_sessions.py)."""
    try:
        pid = int((data_dir / "daemon.pid").read_text(encoding="utf-8").strip())
    except (OSError, ValueError):
        return
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            cmdline = Path(f"/proc/{pid}/cmdline").read_bytes()
        except OSError:
            return  # gone
        if DAEMON.encode() not in cmdline:
            return  # the pid was reused by something else
        time.sleep(0.1)
    log.warning("the previous %s (pid %s) of %s is still running after %.0f s", DAEMON, pid, data_dir, timeout_s)


def running_owner(data_dir: Path) -> dict | None:
    """``owner.json`` of the live process running the embedded database in ``data_dir``, else None."""
    data_dir = Path(data_dir)
    lock = data_dir / "owner.lock"
    if not lock.exists():
        return None
    fd = os.open(lock, os.O_RDWR)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        try:
            return json.loads((data_dir / "owner.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return {"pid": "?", "uri": None}
    finally:
        os.close(fd)  # closing drops a lock taken here; a held lock stays with its owner
    return None


def free_port() -> int:
    """A free TCP port on 127.0.0.1 (the OS picks it)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _daemon_path() -> str:
    """Find the daemon next to this interpreter first (the venv), then on PATH."""
    local = Path(sys.executable).with_name(DAEMON)
    if local.exists():
        return str(local)
    found = shutil.which(DAEMON)
    if not found:
        raise EmbeddedDbError(
            f"{DAEMON} not found: install the embedded database (pip install 'printeps-gateway[embedded-db]') "
            "or set MONGO_URI to a real MongoDB"
        )
    return found


class EmbeddedMongo:
    """One SecantusDB daemon process: start(), uri, stop(). Restartable on the same port and data."""

    def __init__(self, data_dir: Path, port: int = 0, cache: str = "256M", *, oplog_max_entries: int = 20_000,
                 oplog_retention_s: int = 600) -> None:
        self.data_dir = Path(data_dir)
        self.port = port or free_port()
        self.cache = cache
        self.oplog_max_entries = oplog_max_entries
        self.oplog_retention_s = oplog_retention_s
        self.proc: subprocess.Popen[bytes] | None = None
        self._lock_fd: int | None = None

    @property
    def uri(self) -> str:
        return f"mongodb://127.0.0.1:{self.port}/?directConnection=true"

    def start(self, timeout_s: float = 30.0) -> str:
        """Start the daemon and wait until it answers ping; returns the URI."""
        if self.proc and self.proc.poll() is None:
            return self.uri
        self.data_dir.mkdir(parents=True, exist_ok=True)
        self._take_ownership()
        _wait_for_previous_daemon(self.data_dir, timeout_s)
        logfile = open(self.data_dir / "secantusd.log", "ab")
        cmd = [_daemon_path(), "--host", "127.0.0.1", "--port", str(self.port), "--storage-path",
               str(self.data_dir / "data"), "--cache-size", self.cache, "--log-level", "WARNING",
               "--oplog-max-entries", str(self.oplog_max_entries),
               "--oplog-retention-seconds", str(self.oplog_retention_s)]
        log.info("starting embedded database: %s", " ".join(cmd))
        self.proc = subprocess.Popen(cmd, stdout=logfile, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                     env=dict(os.environ), start_new_session=True,
                                     preexec_fn=_die_with_parent if sys.platform == "linux" else None)
        logfile.close()
        (self.data_dir / "daemon.pid").write_text(str(self.proc.pid), encoding="utf-8")
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                self._release_ownership()
                raise EmbeddedDbError(
                    f"{DAEMON} exited with code {self.proc.returncode}; see {self.data_dir / 'secantusd.log'}")
            answering = self._answering_pid()
            if answering == self.proc.pid or answering == 0:
                return self.uri
            if answering is not None:  # our daemon cannot have the port: it exits, or is stopped here
                self.stop()
                raise EmbeddedDbError(
                    f"127.0.0.1:{self.port} is already served by another database process (pid {answering}): "
                    f"set store.embedded_port to a free port (0 picks one), or MONGO_URI to join that database")
            time.sleep(0.1)
        self.stop()
        raise EmbeddedDbError(f"{DAEMON} did not answer on 127.0.0.1:{self.port} within {timeout_s:.0f} s")

    def _take_ownership(self) -> None:
        """Lock the data dir for this process, or raise EmbeddedDbHeld naming the holder."""
        if self._lock_fd is not None:
            return
        fd = os.open(self.data_dir / "owner.lock", os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            try:
                owner = json.loads((self.data_dir / "owner.json").read_text(encoding="utf-8"))
            except (OSError, ValueError):
                owner = {"pid": "?"}
            raise EmbeddedDbHeld(self.data_dir, owner) from None
        self._lock_fd = fd
        owner = {"pid": os.getpid(), "command": [Path(sys.argv[0]).name, *sys.argv[1:]], "uri": self.uri,
                 "port": self.port, "started_at": time.time()}
        (self.data_dir / "owner.json").write_text(json.dumps(owner), encoding="utf-8")

    def _release_ownership(self) -> None:
        if self._lock_fd is None:
            return
        try:
            (self.data_dir / "owner.json").unlink()
        except FileNotFoundError:
            pass
        os.close(self._lock_fd)
        self._lock_fd = None

    def _answering_pid(self) -> int | None:
        """The pid of the database answering on this port (0: one that does not say), None if none does.

        Why the pid: a restart on the same port (after an outage) or a configured port another
        server already listens on was answered by that other server, so the start looked done
        while this daemon exited for want of the port, and the gateway wrote to a foreign database."""
        try:
            with pymongo.MongoClient(self.uri, serverSelectionTimeoutMS=300, connectTimeoutMS=300) as client:
                pid = client.admin.command("serverStatus").get("pid")
            return int(pid) if isinstance(pid, int) and not isinstance(pid, bool) else 0
        except pymongo.errors.PyMongoError:
            return None

    def _wait_waking(self, proc: subprocess.Popen[bytes], timeout_s: float) -> None:
        """Wait for the daemon to exit, connecting to its port now and then meanwhile.

        Why: on SIGINT the daemon closes its listening socket and joins its accept thread for up
        to 2 s, but on Linux closing a socket does not wake a thread blocked in ``accept()``: every
        stop took ~2.3 s of nothing. A connection wakes that thread, which then sees it is told to
        stop. (One that comes before the signal is handled is served as any other, and closed.)"""
        deadline = time.monotonic() + timeout_s
        while True:
            try:
                proc.wait(timeout=0.05)
                return
            except subprocess.TimeoutExpired:
                if time.monotonic() >= deadline:
                    raise
            try:
                socket.create_connection(("127.0.0.1", self.port), timeout=0.05).close()
            except OSError:
                pass  # not listening (any more): nothing to wake

    def stop(self, timeout_s: float = 10.0) -> None:
        """Stop with SIGINT (a clean WiredTiger close), escalating only if it does not exit."""
        proc, self.proc = self.proc, None
        try:
            if not proc or proc.poll() is not None:
                return
            for sig, wait in ((signal.SIGINT, timeout_s), (signal.SIGTERM, 5.0), (signal.SIGKILL, 5.0)):
                try:
                    proc.send_signal(sig)
                    self._wait_waking(proc, wait)
                    return
                except subprocess.TimeoutExpired:
                    log.warning("embedded database did not stop on %s", sig.name)
        finally:
            self._release_ownership()
