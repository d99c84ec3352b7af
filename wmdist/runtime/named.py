"""NamedHandle: a Ray actor handle that travels by the actor's name.

A Ray actor handle inside an actor's constructor arguments is serialised with a reference
Ray tracks like an object in the store, and Ray 2.60 prints an error line for every such
actor that may restart (ray-project/ray#53727: the restart fails if that object is lost).
The replay shards, the limiter and the weight broker are handed to collectors, reanalyzers
and the evaluator, which Ray restarts, so their handles cross as names instead: the copy in
the new process looks the actor up (`ray.get_actor`) on first use. The named actors restart
in place (their names stay), so a name stays valid for the whole run.
"""
from __future__ import annotations

import secrets
from typing import Any


def actor_name(role: str, i: int = 0) -> str:
    """A name no other run in this Ray namespace uses (several runs may share a driver)."""
    return f"wmdist-{role}-{i}-{secrets.token_hex(6)}"


class NamedHandle:
    """Forwards attribute access (`h.method.remote(...)`) to the actor called `name`."""

    __slots__ = ("name", "_handle")

    def __init__(self, name: str, handle: Any = None) -> None:
        self.name = name
        self._handle = handle  # resolved on first use where it arrived by pickle

    @property
    def handle(self) -> Any:
        if self._handle is None:
            import ray

            self._handle = ray.get_actor(self.name)
        return self._handle

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__"):  # copy/pickle probes: not forwarded to the actor
            raise AttributeError(attr)
        return getattr(self.handle, attr)

    def __reduce__(self) -> tuple:
        return NamedHandle, (self.name,)

    def __repr__(self) -> str:
        return f"NamedHandle({self.name!r})"


def start_named(actor_class: Any, role: str, i: int, args: tuple, **options: Any) -> NamedHandle:
    """Start actor i of `role` (a `ray.remote` class) under a fresh name; its NamedHandle."""
    name = actor_name(role, i)
    return NamedHandle(name, actor_class.options(name=name, **options).remote(*args))


def unwrap(handle: Any) -> Any:
    """The Ray handle behind a NamedHandle (for `ray.kill`); anything else as it is."""
    return handle.handle if isinstance(handle, NamedHandle) else handle
