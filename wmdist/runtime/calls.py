"""Actor calls that work with Ray or without it.

The roles talk to each other through handles: `handle.method.remote(...)` returns a
reference, `get(ref)` its value. Under Ray these are Ray's own. The local runner
(`wmdist train --local`) wraps each role's object in a `LocalHandle`, whose calls run at
once in this process and return a `Ready`; `get`, `wait` and `put` here accept both, so
the driver, the replay client and every role run unchanged in one process, where a
debugger can step through an update.
"""
from __future__ import annotations

import sys
from typing import Any


class Ready:
    """The outcome of a call that already ran in this process (a value or an exception)."""

    __slots__ = ("value", "error")

    def __init__(self, value: Any = None, error: BaseException | None = None) -> None:
        self.value, self.error = value, error

    def result(self) -> Any:
        if self.error is not None:
            raise self.error
        return self.value


class _Method:
    __slots__ = ("fn",)

    def __init__(self, fn) -> None:
        self.fn = fn

    def remote(self, *args: Any, **kwargs: Any) -> Ready:
        try:
            return Ready(self.fn(*args, **kwargs))
        except Exception as err:  # noqa: BLE001 - delivered by get(), like a Ray task error
            return Ready(error=err)


class LocalHandle:
    """An in-process stand-in for a Ray actor handle around `obj`."""

    def __init__(self, obj: Any) -> None:
        self._obj = obj

    @property
    def local_object(self) -> Any:
        return self._obj

    def __getattr__(self, name: str) -> _Method:
        return _Method(getattr(self._obj, name))


def is_local(x: Any) -> bool:
    return isinstance(x, (Ready, LocalHandle))


def actor_died() -> tuple[type[BaseException], ...]:
    """What a call raises when its actor is gone, for `except actor_died():`.

    Ray's `RayActorError` once Ray is loaded; nothing before, since no actor can have died
    then. So the local runner never imports Ray (the CUDA check runs where Ray is absent).
    """
    exceptions = sys.modules.get("ray.exceptions")
    return (exceptions.RayActorError,) if exceptions is not None else ()


def get(refs: Any, timeout: float | None = None) -> Any:
    """`ray.get` for Ray refs, the value (or raised error) for local ones; lists element-wise."""
    if isinstance(refs, Ready):
        return refs.result()
    if isinstance(refs, list) and all(isinstance(r, Ready) for r in refs):
        return [r.result() for r in refs]  # (an empty list too: no Ray needed for nothing)
    import ray

    return ray.get(refs, timeout=timeout)


def wait(refs: list, num_returns: int = 1, timeout: float | None = None) -> tuple[list, list]:
    """`ray.wait`; local refs are always ready."""
    done = [r for r in refs if isinstance(r, Ready)]
    if done:
        return done[:num_returns], [r for r in refs if r not in done[:num_returns]]
    import ray

    return ray.wait(refs, num_returns=num_returns, timeout=timeout)


def put(value: Any, local: bool) -> Any:
    """`ray.put`, or a `Ready` holding a copy in the local runner (a snapshot, as `ray.put`
    makes one: later changes to `value` must not reach its readers)."""
    if local:
        import copy

        return Ready(copy.deepcopy(value))
    import ray

    return ray.put(value)


def kill(handle: Any) -> None:
    """`ray.kill` without restart; a local handle has nothing to kill."""
    if isinstance(handle, LocalHandle):
        return
    import ray

    from wmdist.runtime.named import unwrap

    ray.kill(unwrap(handle), no_restart=True)
