"""Faults injected into real `wmdist train` processes (real local Ray, real redis-server).

Each run is started in a session of its own, as a terminal would start it, so a SIGINT sent
to its process group is exactly a Ctrl-C: the driver, its redis-server and Ray all get it.
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from wmdist.runtime.checkpoint import latest_checkpoint, load_counters

FAKE = str(Path(__file__).parent / "fake.yaml")
ROOT = Path(__file__).resolve().parents[2]


def _terminal_signals() -> None:
    """In the child before exec: SIGINT as a terminal's foreground job has it. A suite started as
    a background job (`cmd &` in a script) inherits SIGINT ignored, and Python then installs no
    KeyboardInterrupt handler, so the Ctrl-C these tests send would be lost."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


class Train:
    """`wmdist train ...` in a new session, its output collected on a thread."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "wmdist.cli", "train", *args], cwd=ROOT,
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     start_new_session=True, preexec_fn=_terminal_signals)
        self.lines: list[str] = []
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    @property
    def text(self) -> str:
        return "\n".join(self.lines)

    def wait_for(self, what, timeout: float = 120.0, label: str = ""):
        """Poll `what()` until it returns something truthy."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            got = what()
            if got:
                return got
            if self.proc.poll() is not None:
                time.sleep(0.5)  # let the reader catch up before the last look
                got = what()
                if got:
                    return got
                pytest.fail(f"exited {self.proc.returncode} while waiting for {label}:\n{self.text}")
            time.sleep(0.2)
        pytest.fail(f"timed out waiting for {label}:\n{self.text}")

    def run_dir(self) -> Path:
        line = self.wait_for(lambda: next((ln for ln in self.lines if ln.startswith("wmdist: run directory ")), None),
                             label="the run directory")
        return Path(line.split("wmdist: run directory ", 1)[1].strip())

    def ctrl_c(self, timeout: float = 120.0) -> int:
        os.killpg(self.proc.pid, signal.SIGINT)
        rc = self.proc.wait(timeout)
        self.reader.join(5)
        return rc

    def exit_status(self, timeout: float) -> int:
        """Wait for the command to end (its output read to the last line)."""
        rc = self.proc.wait(timeout)
        self.reader.join(5)
        return rc

    def kill(self) -> None:
        self.proc.kill()
        self.proc.wait(30)
        self.reader.join(5)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return Path(f"/proc/{pid}").exists() and "Z" not in Path(f"/proc/{pid}/stat").read_text().split()[2]


def _redis_pid(run_dir: Path) -> int | None:
    try:
        pid = int((run_dir / "redis" / "redis.pid").read_text().strip())
    except (OSError, ValueError):
        return None
    return pid if _alive(pid) else None


def _checkpoint_after(run_dir: Path, updates: int):
    ckpt = latest_checkpoint(run_dir)
    if ckpt is None:
        return None
    c = load_counters(ckpt)
    return c if c["updates"] > updates else None


def _wait_gone(pid: int, timeout: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if not _alive(pid):
            return True
        time.sleep(0.1)
    return False


RUN = ["run.max_minutes=10", "checkpoint.every_seconds=2", "run.log_every_seconds=0.5"]


@pytest.mark.slow
def test_redis_run_survives_a_killed_server_a_killed_driver_and_ctrl_c(tmp_path):
    """redis-server SIGKILLed mid-run: the driver restarts it and the run goes on. The driver
    SIGKILLed: its redis-server goes too, and --resume continues counters, weights and replay.
    Ctrl-C: a final checkpoint, exit 130, nothing left running, no traceback."""
    run = Train(FAKE, "--set", f"run.dir={tmp_path}", "replay.backend=redis", "replay.redis_appendfsync=always", "replay.shards=2",
                *RUN)
    try:
        run_dir = run.run_dir()
        first = run.wait_for(lambda: _checkpoint_after(run_dir, 0), label="a first checkpoint")
        old = run.wait_for(lambda: _redis_pid(run_dir), label="redis-server")
        os.kill(old, signal.SIGKILL)
        new = run.wait_for(lambda: (p := _redis_pid(run_dir)) and p != old and p, label="redis-server restarted")
        # the run goes on: checkpoints keep coming, each holding more updates and the replay
        later = run.wait_for(lambda: _checkpoint_after(run_dir, first["updates"]), label="a checkpoint after it")
        later = run.wait_for(lambda: _checkpoint_after(run_dir, later["updates"]), label="a second one")
        assert later["restarts"]["redis"] >= 1
        run.kill()  # SIGKILL the driver: a crash
        assert _wait_gone(new), "the driver's redis-server outlived it"
    finally:
        if run.proc.poll() is None:
            run.kill()
    saved = load_counters(latest_checkpoint(run_dir))

    resumed = Train("--resume", str(run_dir), "--set", *RUN)
    try:
        resumed.wait_for(lambda: any("resumed from" in ln for ln in resumed.lines), label="resume")
        line = next(ln for ln in resumed.lines if "resumed from" in ln)
        assert f"at {saved['env_steps']} env steps, {saved['updates']} updates" in line
        resumed.wait_for(lambda: _checkpoint_after(run_dir, saved["updates"]), label="a checkpoint after resume")
        server = _redis_pid(run_dir)
        rc = resumed.ctrl_c()
    finally:
        if resumed.proc.poll() is None:
            resumed.kill()
    assert rc == 130, resumed.text
    assert "Traceback" not in resumed.text and "checkpoint written" in resumed.text
    final = load_counters(latest_checkpoint(run_dir))
    assert final["updates"] > saved["updates"] and final["env_steps"] >= saved["env_steps"]
    assert final["version"] >= saved["version"]
    assert server is not None and _wait_gone(server), "redis-server left running after Ctrl-C"
    limiter = json.loads((latest_checkpoint(run_dir) / "replay" / "limiter.json").read_text())
    assert limiter, "the final checkpoint holds no replay state"


@pytest.mark.slow
def test_sigterm_to_the_process_group_checkpoints_and_exits_143(tmp_path):
    """`kill PID`, `docker stop`, `timeout`, `kill -TERM -PGID`, Slurm's scancel: SIGTERM ends a
    run the way Ctrl-C does (the redis test above): a final checkpoint with the replay, exit
    status 143 (128 + SIGTERM), no traceback, and the resume command. Sent to the whole
    process group, it used to reach Ray's GCS and raylet too, which died with it: the driver
    hung 60 s and exited 1 with no final checkpoint. The driver now runs in a session of its
    own behind a relay (`runtime/own_session.py`; the relay alone is tested in
    test_own_session.py), so the driver sees one SIGTERM either way, and nothing of the run's
    Ray is left."""
    run = Train(FAKE, "--set", f"run.dir={tmp_path}", *RUN)
    try:
        run_dir = run.run_dir()
        run.wait_for(lambda: _checkpoint_after(run_dir, 0), label="a first checkpoint")
        before = load_counters(latest_checkpoint(run_dir))
        time.sleep(1.0)
        session = _session_of(run.proc.pid)  # the driver and Ray's processes
        assert session and run.proc.pid not in session
        os.killpg(run.proc.pid, signal.SIGTERM)  # Train starts the command as its group's leader
        rc = run.exit_status(60)
    finally:
        if run.proc.poll() is None:
            run.kill()
    assert rc == 143, run.text
    assert "interrupted" in run.text and "checkpoint written" in run.text
    assert not any(s in run.text for s in ("Traceback", "SIGTERM received", "GCS"))
    final = load_counters(latest_checkpoint(run_dir))
    assert final["updates"] >= before["updates"]
    assert (latest_checkpoint(run_dir) / "replay").is_dir()
    assert f"wmdist train --resume {run_dir}" in run.text
    assert all(_wait_gone(p) for p in session), "processes of the run's session left running"


@pytest.mark.slow
def test_killed_services_and_learner_come_back_until_the_learners_restarts_are_used_up(tmp_path):
    """The weight broker and the rate limiter hold nothing a restart cannot rebuild (the newest
    snapshot's refs; counts, and the size the shards report): Ray restarts them, calls made
    meanwhile are retried, and training goes on (was: a dead broker failed the learner's next
    publish and ended the run; a dead limiter stalled it). Then the learner's process killed
    (the kernel's OOM killer, a crash): a new learner starts from the latest checkpoint and
    the run goes on (counted in the checkpoint's restarts); once `learner.max_restarts` are
    used up, the next death ends the run in one line that names the resume command."""
    run = Train(FAKE, "--set", f"run.dir={tmp_path}", *RUN, "learner.max_restarts=1", "replay.min_size=200")
    try:
        run_dir = run.run_dir()
        start = run.wait_for(lambda: _checkpoint_after(run_dir, 0), label="a first checkpoint")
        session = _session_of(run.proc.pid)
        for role in ("WeightBroker", "LimiterActor"):
            os.kill(run.wait_for(lambda role=role: _role_pid(session, role), label=role), signal.SIGKILL)
        # training goes on, weights are still published (through the new broker), and the new
        # limiter was given the shards' size (counted)
        first = run.wait_for(lambda: (c := _checkpoint_after(run_dir, start["updates"] + 20))
                             and c["env_steps"] > start["env_steps"] and c["version"] > start["version"]
                             and c["restarts"].get("limiter") == 1 and c, label="training after both died")
        session = _session_of(run.proc.pid)
        old = run.wait_for(lambda: _role_pid(session, "LearnerRole"), label="the learner's process")
        os.kill(old, signal.SIGKILL)
        # a checkpoint after the restart holds the new learner's updates beyond the first's
        later = run.wait_for(lambda: (c := _checkpoint_after(run_dir, first["updates"]))
                             and c["restarts"].get("learner", 0) == 1 and c, label="a checkpoint after the restart")
        new = _role_pid(_session_of(run.proc.pid), "LearnerRole")
        assert new and new != old and later["env_steps"] >= first["env_steps"]
        os.kill(new, signal.SIGKILL)  # its one restart is used: the run ends
        rc = run.exit_status(120)
    finally:
        if run.proc.poll() is None:
            run.kill()
    assert rc == 1, run.text
    err = [ln for ln in run.lines if ln.startswith("wmdist: error:")]
    assert len(err) == 1 and "the learner's process died" in err[0] and "learner.max_restarts=1" in err[0]
    # Ray's paragraphs on each death go to the run's log, not the console
    assert "(raylet)" not in run.text and "Ray: " in (run_dir / "wmdist.log").read_text()
    assert f"wmdist train --resume {run_dir}" in err[0] and "Traceback" not in run.text


def _role_pid(session: list[int], role: str) -> int | None:
    """The pid of the run's Ray worker that runs actor class `role` (its title is `ray::ROLE...`)."""
    for pid in session:
        try:
            title = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0].decode()
        except OSError:
            continue
        if title.startswith(f"ray::{role}"):
            return pid
    return None


def _session_of(leader: int) -> list[int]:
    """Pids of the session the relay `leader` started its driver in (the driver, Ray's processes)."""
    kids = [int(p) for p in Path(f"/proc/{leader}/task/{leader}/children").read_text().split()]
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if kids and int(fields[3]) == kids[0]:  # field 6 of stat: the session id
            out.append(int(stat.parent.name))
    return out
