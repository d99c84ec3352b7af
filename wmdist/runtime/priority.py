"""A role's OS priority: background work that should use only the CPU the others leave idle.

A reanalyzer (EfficientZero, MuZero Reanalyze) always has work: refreshing targets for 99%
of samples is more than one core does. On a small machine the kernel then splits the cores
evenly between it, the learner and the collectors, and the learner, which sets the run's
pace through the replay ratio, gets a fraction of a core. A nice level above the learner's
makes the scheduler give the reanalyzer the CPU the learner and collectors do not use
(at nice 10 a busy neighbour gets about 9x its share) instead of an equal split.

On Linux a nice level belongs to a thread, not the process, and a new thread inherits its
creator's. So every thread that exists is lowered, and `lower_priority` is safe to call
again from whichever thread runs the role's calls.
"""
from __future__ import annotations

import os


def _threads() -> list[int]:
    """Thread ids of this process (Linux), or [0] (the caller) where /proc has no task list."""
    try:
        return [int(t) for t in os.listdir("/proc/self/task")]
    except (FileNotFoundError, NotADirectoryError, PermissionError):
        return [0]


def niceness(tid: int = 0) -> int:
    """The nice level of thread `tid` (0: the calling one)."""
    return os.getpriority(os.PRIO_PROCESS, tid)


def lower_priority(by: int, base: int | None = None) -> int:
    """Set every thread of this process to nice `base + by` (base: the calling thread's level
    the first time; at most 19). Never raises it back: a thread already lower stays. Returns
    the target level; `by` 0 does nothing."""
    if by <= 0:
        return niceness()
    target = min(19, (niceness() if base is None else base) + by)
    for tid in _threads():
        try:
            if niceness(tid) < target:
                os.setpriority(os.PRIO_PROCESS, tid, target)
        except (ProcessLookupError, PermissionError):  # a thread that just exited
            continue
    return target
