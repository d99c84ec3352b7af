"""`wmdist train` runs its driver in a session of its own, behind a small relay process.

A signal sent to a whole process group (`timeout`, `kill -TERM -PGID`, Slurm's `scancel`, a
supervisor that stops a process group) reached Ray's own processes as well as the driver. Ray
blocks SIGINT in them but not SIGTERM, so its GCS and raylet died at once; the driver then
waited 60 s for them, wrote no final checkpoint and printed no resume line.

The command's process now starts the driver as a child in a new session (a group nothing
outside sends to) and relays to it the signals it gets itself: SIGINT and SIGTERM as they are,
SIGHUP (the terminal closed) as SIGTERM; a signal ignored when the command started stays
ignored. The driver handles them as before (drain, final
checkpoint, shut Ray down) and the relay exits with the driver's status. The child dies
with the relay (SIGKILL when it dies), so `kill -9` on the command stays the crash it was.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Sequence

from wmdist.runtime.parent_death import signal_on_parent_death

CHILD_ENV = "WMDIST_DRIVER_SESSION"  # set in the child: it is the driver, it starts no relay
RELAYED = {signal.SIGINT: signal.SIGINT, signal.SIGTERM: signal.SIGTERM, signal.SIGHUP: signal.SIGTERM}


_die_with_relay = signal_on_parent_death(signal.SIGKILL)  # in the child: as if one process with the relay


def wanted() -> bool:
    """Whether this process should relay (not the driver child itself; Linux only)."""
    return os.environ.get(CHILD_ENV) != "1" and sys.platform.startswith("linux")


def wmdist_command(argv: Sequence[str]) -> list[str]:
    """The command line of `wmdist *argv` run by this interpreter."""
    return [sys.executable, "-m", "wmdist.cli", *argv]


def run_relayed(command: Sequence[str]) -> int:
    """Run `command` as a child in a new session, relaying signals -> its exit status (128 + N
    if a signal N ended it)."""
    env = dict(os.environ, **{CHILD_ENV: "1"})
    # the relay installs its handlers first: a signal that comes before the child exists
    # is held and sent as soon as it does, so none is lost in between
    held: list[int] = []
    child: list[subprocess.Popen] = []

    def relay(signum: int, _frame) -> None:
        if not child:
            held.append(RELAYED[signum])
            return
        try:
            child[0].send_signal(RELAYED[signum])
        except ProcessLookupError:  # it is exiting already
            pass

    # a signal this process ignores (SIGHUP under nohup, SIGINT in a background job) stays
    # ignored: the child inherits that, as it would have without the relay
    previous = {s: signal.signal(s, relay) for s in RELAYED if signal.getsignal(s) != signal.SIG_IGN}
    try:
        child.append(subprocess.Popen(list(command), env=env,
                                      start_new_session=True, preexec_fn=_die_with_relay))
        for s in held:
            child[0].send_signal(s)
        rc = child[0].wait()  # a relayed signal interrupts the wait, which Python then resumes
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
    if rc < 0:  # killed outright (the kernel's OOM killer, kill -9 on the driver): say so
        name = signal.Signals(-rc).name if -rc in signal.Signals._value2member_map_ else f"signal {-rc}"
        print(f"wmdist: the driver was killed by {name}; resume from its run directory's last checkpoint "
              f"with `wmdist train --resume RUN_DIR`", file=sys.stderr, flush=True)
        return 128 - rc
    return rc
