"""Launcher for a private redis-server (a run's replay store, and the tests' server).

Binds 127.0.0.1 on a free port, requires a generated password, keeps its data and AOF in
the given directory. The password and the config that holds it are written with mode 0600
(never on the command line, where `ps` would show it). Stopped by `stop()`.

The server runs in a session of its own, so a terminal's Ctrl-C reaches the driver only and
the driver decides when replay stops (after its final checkpoint). With `die_with_parent`
the kernel sends it SIGTERM (a clean AOF shutdown) if the process that started it dies,
even by SIGKILL; a server left by an older process on the same directory is found through
its pid file and stopped before a new one starts (`stop_stale`).
"""
from __future__ import annotations

import os
import secrets
import shutil
import signal
import socket
import subprocess
import time

import redis

from wmdist.runtime.parent_death import signal_on_parent_death

PASSWORD_FILE = "redis.pass"
PID_FILE = "redis.pid"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _write_private(path: str, text: str) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    os.chmod(path, 0o600)


# in the child before exec: SIGTERM when the parent dies (elsewhere than Linux the pid file
# still lets a resume stop it)
_die_with_parent = signal_on_parent_death(signal.SIGTERM)


def _serves(pid: int, directory: str) -> bool:
    """pid is a live redis-server working in `directory` (redis rewrites its command line, so
    the working directory, where we start it, is what identifies it)."""
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            if b"redis-server" not in f.read():
                return False
        return os.path.realpath(os.readlink(f"/proc/{pid}/cwd")) == os.path.realpath(directory)
    except OSError:
        return False


def stop_stale(directory: str, timeout: float = 15.0) -> bool:
    """Stop a redis-server that an earlier process left running on `directory` (its pid file
    names it). True if one was stopped."""
    directory = os.path.abspath(directory)
    try:
        with open(os.path.join(directory, PID_FILE), encoding="utf-8") as f:
            pid = int(f.read().strip())
    except (OSError, ValueError):
        return False
    if not _serves(pid, directory):
        return False  # gone, or the pid was reused by another program: leave it alone
    os.kill(pid, signal.SIGTERM)  # a clean shutdown: the AOF is flushed
    deadline = time.monotonic() + timeout
    while _serves(pid, directory) and time.monotonic() < deadline:
        time.sleep(0.05)
    if _serves(pid, directory):
        os.kill(pid, signal.SIGKILL)
    return True


class RedisServer:
    def __init__(self, directory: str, appendfsync: str = "everysec", aof: bool = True, port: int = 0,
                 die_with_parent: bool = False) -> None:
        if appendfsync not in ("always", "everysec", "no"):
            raise ValueError(f"appendfsync must be always, everysec or no, got {appendfsync!r}")
        exe = shutil.which("redis-server")
        if exe is None:
            raise ValueError("redis-server is not installed (apt-get install redis-server, or `make system-deps`)")
        self.exe = exe
        self.dir = os.path.abspath(directory)
        os.makedirs(self.dir, mode=0o700, exist_ok=True)
        self.password_file = os.path.join(self.dir, PASSWORD_FILE)
        if not os.path.exists(self.password_file):
            _write_private(self.password_file, secrets.token_urlsafe(24))
        with open(self.password_file, encoding="utf-8") as f:
            self.password = f.read().strip()
        self.port = port or free_port()
        self.die_with_parent = die_with_parent
        self.conf = os.path.join(self.dir, "redis.conf")
        _write_private(self.conf, "\n".join([
            "bind 127.0.0.1", "protected-mode yes", f"port {self.port}", f"dir {self.dir}",
            f"requirepass {self.password}", f"appendonly {'yes' if aof else 'no'}",
            f"appendfsync {appendfsync}", 'save ""', "daemonize no", "loglevel warning",
            "logfile redis.log", "maxmemory-policy noeviction", f"pidfile {os.path.join(self.dir, PID_FILE)}", "",
        ]))
        self.proc: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        """URL without the password (pass `password_file` alongside)."""
        return f"redis://127.0.0.1:{self.port}/0"

    def client(self) -> redis.Redis:
        return redis.Redis(host="127.0.0.1", port=self.port, password=self.password)

    def start(self, timeout: float = 10.0) -> "RedisServer":
        stop_stale(self.dir)
        self.proc = subprocess.Popen([self.exe, self.conf], cwd=self.dir, stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                     start_new_session=True,  # not in the terminal's process group
                                     preexec_fn=_die_with_parent if self.die_with_parent else None)
        deadline = time.monotonic() + timeout
        while True:
            try:
                if self.client().ping():
                    return self
            except (redis.ConnectionError, redis.BusyLoadingError):
                pass
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"redis-server did not start on 127.0.0.1:{self.port} (see {self.dir}/redis.log)")
            time.sleep(0.02)

    @property
    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def restart(self, timeout: float = 30.0) -> "RedisServer":
        """Start again on the same port and directory (the AOF brings the data back)."""
        if self.alive:
            return self
        self.proc = None
        return self.start(timeout)

    def kill(self) -> None:
        """SIGKILL (for durability tests): no shutdown save, only what the AOF holds survives."""
        if self.proc and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGKILL)
            self.proc.wait()

    def stop(self) -> None:
        if self.proc and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.kill()
        self.proc = None
