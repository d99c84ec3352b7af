"""`param`: a dataclass field that carries its one-line doc and its valid range.

Every config field in wmdist is declared with `param(...)` so that the doc lives where the
field is declared and the loader can check ranges before anything starts.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Sequence

# The most layers or blocks a network-depth field accepts: far past any paper's model (MuZero:
# 16 residual blocks), low enough that a typo such as 1e12 is refused instead of building forever.
MAX_LAYERS = 1000
# The same guard for the work of one decision (search simulations, CEM candidates, CMA-ES population and
# rollouts; MuZero's board games: 800) and for horizons and refit counts (Dreamer: 15, PlaNet: 12).
MAX_PER_DECISION = 100_000
MAX_HORIZON = 10_000


def param(
    default: Any,
    doc: str,
    *,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    choices: Sequence[Any] | None = None,
) -> Any:
    """Declare a config field with its doc and optional bounds (checked by the loader)."""
    meta = {"doc": doc, "ge": ge, "gt": gt, "le": le, "lt": lt, "choices": tuple(choices) if choices else None}
    if isinstance(default, (list, dict, set)):
        value = default
        return dataclasses.field(default_factory=lambda: type(value)(value), metadata=meta)
    if dataclasses.is_dataclass(default) and not isinstance(default, type):
        value = default
        return dataclasses.field(default_factory=lambda: dataclasses.replace(value), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def section(cls: type, doc: str) -> Any:
    """Declare a nested config section (a dataclass built with its defaults)."""
    return dataclasses.field(default_factory=cls, metadata={"doc": doc})
