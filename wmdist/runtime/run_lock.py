"""One `wmdist train` per run directory at a time.

A second `wmdist train --resume RUN` while the first still runs (another terminal, a job
retried by a scheduler) would write the same checkpoints, logs and config from two drivers.
The driver holds an exclusive `flock` on the run directory itself for its whole life (no
lock file: a refused resume leaves the directory exactly as it was); the kernel drops it
when the process exits, however it exits (kill -9 included), so a lock never outlives its
run and there is nothing stale to clean up. Readers (`wmdist eval`, `dream`, `monitor`) do
not take it.
"""
from __future__ import annotations

import fcntl
import os
from pathlib import Path

from wmdist.config.errors import ConfigError


class RunLock:
    """Held from `acquire` until `release` (or the process's end)."""

    def __init__(self, run_dir: str | Path) -> None:
        self.path = Path(run_dir)
        self._fd: int | None = None

    def acquire(self) -> "RunLock":
        """Take the lock, or raise ConfigError if another process holds it."""
        try:
            fd = os.open(self.path, os.O_RDONLY | os.O_DIRECTORY)
        except OSError as err:
            raise ConfigError(f"{self.path}: cannot open the run directory ({err.strerror or err})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise ConfigError(f"{self.path} is in use by another wmdist train; stop that one first, or resume once "
                              f"it has ended") from None
        except OSError:  # a filesystem without flock (some network mounts): run unguarded, as before
            os.close(fd)
            return self
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is not None:
            fcntl.flock(self._fd, fcntl.LOCK_UN)
            os.close(self._fd)
            self._fd = None
