"""The relay in front of `wmdist train` (`runtime/own_session.py`), with a real child process
in place of the driver: a script that writes down each signal it gets. The relay must put
the child in a session of its own, pass SIGINT and SIGTERM on, turn SIGHUP into SIGTERM,
keep ignoring what was ignored when it started (nohup), give back the child's exit status,
and take the child with it when it is killed."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

# the stand-in driver: reports its session, logs each signal; SIGTERM ends it with 143
CHILD = textwrap.dedent("""
    import os, signal, sys, time
    log = open(sys.argv[1], "a", buffering=1)
    def on(signum, _frame):
        log.write(f"{signal.Signals(signum).name}\\n")
        if signum == signal.SIGTERM:
            sys.exit(143)
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(s) != signal.SIG_IGN:
            signal.signal(s, on)
    log.write(f"ready {os.getpid()} {os.getsid(0)}\\n")
    while True:
        time.sleep(0.05)
""")

# the relay, as `wmdist train` starts it, with the stand-in as its command
RELAY = textwrap.dedent("""
    import signal, sys
    from wmdist.runtime.own_session import run_relayed
    # start from a terminal's dispositions whatever ran the tests (nohup, a background job)
    for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(s, signal.SIG_DFL)
    if sys.argv[3] == "nohup":
        signal.signal(signal.SIGHUP, signal.SIG_IGN)
    sys.exit(run_relayed([sys.executable, sys.argv[1], sys.argv[2]]))
""")


def _start(tmp_path: Path, mode: str = "") -> tuple[subprocess.Popen, Path, int]:
    (tmp_path / "child.py").write_text(CHILD)
    log = tmp_path / "signals.log"
    relay = subprocess.Popen([sys.executable, "-c", RELAY, str(tmp_path / "child.py"), str(log), mode or "-"],
                             start_new_session=True, env={**os.environ, "WMDIST_DRIVER_SESSION": "0"})
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        lines = log.read_text().splitlines() if log.exists() else []
        if lines and lines[0].startswith("ready"):
            _, pid, sid = lines[0].split()
            assert int(sid) == int(pid) != relay.pid  # the child leads a session of its own
            return relay, log, int(pid)
        time.sleep(0.05)
    relay.kill()
    pytest.fail("the child never started")


def _signals(log: Path) -> list[str]:
    return log.read_text().splitlines()[1:]


def _gone(pid: int, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        stat = Path(f"/proc/{pid}/stat")
        if stat.exists() and stat.read_text().rsplit(")", 1)[1].split()[0] == "Z":
            return True
        time.sleep(0.05)
    return False


def test_group_signals_reach_the_child_once_and_its_status_comes_back(tmp_path):
    relay, log, child = _start(tmp_path)
    try:
        os.killpg(relay.pid, signal.SIGINT)  # a terminal's Ctrl-C: the relay's group only
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and _signals(log) != ["SIGINT"]:
            time.sleep(0.05)
        assert _signals(log) == ["SIGINT"] and relay.poll() is None  # relayed once; the child decides
        os.killpg(relay.pid, signal.SIGHUP)  # the terminal closed: a graceful stop
        assert relay.wait(10) == 143
    finally:
        if relay.poll() is None:
            relay.kill()
    assert _signals(log) == ["SIGINT", "SIGTERM"]
    assert _gone(child)


def test_sigterm_to_the_group_is_relayed_as_is(tmp_path):
    relay, log, _ = _start(tmp_path)
    os.killpg(relay.pid, signal.SIGTERM)
    assert relay.wait(10) == 143
    assert _signals(log) == ["SIGTERM"]


def test_under_nohup_a_hangup_is_still_ignored(tmp_path):
    relay, log, _ = _start(tmp_path, "nohup")
    try:
        os.killpg(relay.pid, signal.SIGHUP)
        time.sleep(1.0)
        assert relay.poll() is None and _signals(log) == []
        relay.terminate()
        assert relay.wait(10) == 143
    finally:
        if relay.poll() is None:
            relay.kill()


def test_killing_the_relay_takes_the_child_with_it(tmp_path):
    """`kill -9` on the command stays a crash: no graceful stop, nothing left running."""
    relay, log, child = _start(tmp_path)
    relay.kill()
    relay.wait(10)
    assert _gone(child), "the child outlived its relay"
    assert _signals(log) == []


def test_a_driver_killed_outright_is_one_line_and_128_plus_the_signal(tmp_path):
    (tmp_path / "child.py").write_text(CHILD)
    log = tmp_path / "signals.log"
    relay = subprocess.Popen([sys.executable, "-c", RELAY, str(tmp_path / "child.py"), str(log), "-"],
                             start_new_session=True, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and not (log.exists() and log.read_text().startswith("ready")):
        time.sleep(0.05)
    os.kill(int(log.read_text().split()[1]), signal.SIGKILL)  # the OOM killer's way
    _, err = relay.communicate(timeout=10)
    assert relay.returncode == 137
    assert err.strip().splitlines() == [err.strip()] and "killed by SIGKILL" in err and "--resume" in err
