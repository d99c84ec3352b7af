"""A child process that is told when its parent dies (Linux `prctl(PR_SET_PDEATHSIG)`).

Used as `subprocess.Popen(preexec_fn=...)`: the private redis-server gets SIGTERM (a clean AOF
shutdown) when the driver dies; the driver behind `wmdist train`'s relay gets SIGKILL when the
relay dies, so the two end as one process. Elsewhere than Linux it does nothing.
"""
from __future__ import annotations

import signal
from typing import Callable

_PR_SET_PDEATHSIG = 1  # prctl(2) option: signal this process when its parent thread dies


def signal_on_parent_death(sig: signal.Signals) -> Callable[[], None]:
    """A `preexec_fn` that has the child sent `sig` when its parent dies."""
    def preexec() -> None:
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, sig, 0, 0, 0)
        except (OSError, AttributeError):  # not Linux
            pass

    return preexec
