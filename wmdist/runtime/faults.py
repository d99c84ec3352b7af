"""How the driver reads a failed call: a dead process, a constructor that raised, or a
replay store that is briefly unreachable (a redis-server restarting), and one line for each.

Remote errors arrive wrapped (`RayTaskError(ConnectionError)`, tracebacks as text), so the
classes are matched by name along the error's MRO and its cause chain.
"""
from __future__ import annotations

import re

# Actor errors that mean "the process died" (Ray restarts collectors and reanalyzers).
ACTOR_DIED = ("RayActorError", "ActorDiedError", "ActorUnavailableError")
# redis-py errors that a restarted or reconnecting server clears: worth retrying.
TRANSIENT = ("ConnectionError", "TimeoutError", "BusyLoadingError", "ConnectionRefusedError",
             "ConnectionResetError", "BrokenPipeError")


def _names(err: BaseException) -> set[str]:
    out: set[str] = set()
    seen: set[int] = set()
    e: BaseException | None = err
    while e is not None and id(e) not in seen:
        seen.add(id(e))
        out.update(t.__name__ for t in type(e).__mro__)
        cause = getattr(e, "cause", None)  # RayTaskError keeps the remote exception here
        e = cause if isinstance(cause, BaseException) else (e.__cause__ or e.__context__)
    return out


def died(err: BaseException) -> bool:
    """The called actor's own process died (not one it called in turn)."""
    return any(t.__name__ in ACTOR_DIED for t in type(err).__mro__)


def failed_to_start(err: BaseException) -> bool:
    """The actor's constructor raised (Ray reports it as a death in the creation task)."""
    return died(err) and "creation task" in str(err)


def transient(err: BaseException) -> bool:
    """The replay store could not be reached (retry once it is back); never a dead actor."""
    return not died(err) and bool(_names(err) & set(TRANSIENT))


def out_of_memory(err: BaseException) -> str | None:
    """One line for a process Ray's memory monitor killed (its own message is a paragraph of
    advice that ends mid-sentence when cut to a line), else None."""
    if "OutOfMemoryError" not in _names(err):
        return None
    used = re.search(r"(\d+(?:\.\d+)?\s*GB\s*/\s*\d+(?:\.\d+)?\s*GB)", str(err))
    at = f" ({used.group(1)} used)" if used else ""
    return (f"OutOfMemoryError: Ray's memory monitor killed it: the machine's memory ran short{at}; "
            f"other jobs on the machine, or lower learner.batch_size / replay.capacity_steps")


def death(err: BaseException) -> str:
    """Why an actor's process died, briefly (Ray's text is a paragraph of possible causes)."""
    oom = out_of_memory(err)
    if oom:
        return oom
    kind = re.search(r"Worker exit type: (\w+)", str(err))
    if kind and kind.group(1) == "SYSTEM_ERROR":
        return "killed by a signal, by the kernel's OOM killer, or crashed; Ray's worker logs say which"
    return one_line(err)


def root_cause(err: BaseException) -> str:
    """The last 'SomeError: message' line of a remote traceback, else the last line."""
    oom = out_of_memory(err)
    if oom:
        return oom
    lines = [ln.strip() for ln in str(err).splitlines() if ln.strip()]
    for ln in reversed(lines):
        head = ln.split(":", 1)[0]
        if head.isidentifier() and (head.endswith("Error") or head.endswith("Exception")):
            return ln[:400]
    return lines[-1][:400] if lines else type(err).__name__


def one_line(err: BaseException) -> str:
    oom = out_of_memory(err)
    if oom:
        return oom
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[-1] if text else ''}"[:400]
