"""Launcher for a private redis-server (a run's replay store, and the tests' server).

Binds 127.0.0.1 on a free port, requires a generated password, keeps its data and AOF in
the given directory. The password and the config that holds it are written with mode 0600
(never on the command line, where `ps` would show it). Stopped by `stop()`.
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

PASSWORD_FILE = "redis.pass"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _write_private(path: str, text: str) -> None:
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    os.chmod(path, 0o600)


class RedisServer:
    def __init__(self, directory: str, appendfsync: str = "everysec", aof: bool = True, port: int = 0) -> None:
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
        self.conf = os.path.join(self.dir, "redis.conf")
        _write_private(self.conf, "\n".join([
            "bind 127.0.0.1", "protected-mode yes", f"port {self.port}", f"dir {self.dir}",
            f"requirepass {self.password}", f"appendonly {'yes' if aof else 'no'}",
            f"appendfsync {appendfsync}", 'save ""', "daemonize no", "loglevel warning",
            "logfile redis.log", "maxmemory-policy noeviction", "",
        ]))
        self.proc: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        """URL without the password (pass `password_file` alongside)."""
        return f"redis://127.0.0.1:{self.port}/0"

    def client(self) -> redis.Redis:
        return redis.Redis(host="127.0.0.1", port=self.port, password=self.password)

    def start(self, timeout: float = 10.0) -> "RedisServer":
        self.proc = subprocess.Popen([self.exe, self.conf], cwd=self.dir, stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
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
