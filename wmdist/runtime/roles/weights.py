"""Versioned weight snapshots: the learner publishes each version with one `ray.put`; the
broker only holds the newest reference, so the object store keeps one snapshot alive."""
from __future__ import annotations

from typing import Any


class WeightBroker:
    """A tiny Ray actor: (version, [ObjectRef, ...]) of the newest snapshot: the actors' weights,
    then optionally the evaluator's own (`Learner.get_eval_weights`).

    The refs travel inside a list so Ray hands the references themselves, not their values.
    """

    def __init__(self) -> None:
        self.version = -1
        self.ref: list[Any] = []

    def publish(self, version: int, ref_box: list[Any]) -> None:
        if version > self.version:
            self.version, self.ref = version, ref_box

    def latest(self, known_version: int = -1) -> tuple[int, list[Any]]:
        """The newest (version, [ref]); an empty box when the caller is already current."""
        if self.version <= known_version:
            return self.version, []
        return self.version, self.ref

    def current_version(self) -> int:
        return self.version


def pull(broker: Any, known_version: int, timeout: float | None = 30.0,
         evaluator: bool = False) -> tuple[int, dict | None]:
    """(version, weights) if a newer snapshot than `known_version` exists, else (version, None).
    With `evaluator`, the evaluator's own weights where the learner published them."""
    from wmdist.runtime.calls import get

    version, box = get(broker.latest.remote(known_version), timeout=timeout)
    if not box:
        return version, None
    return version, get(box[1] if evaluator and len(box) > 1 else box[0], timeout=timeout)
