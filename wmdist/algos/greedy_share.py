"""A share of each collector's envs that act greedily while the rest explore.

Exploring envs (visit counts at a temperature, an actor's sample) end their episodes early;
a greedy policy that holds a task for hundreds of steps then meets states (a cart drifting
towards the edge) that replay never holds, and nothing teaches it to avoid them. Ape-X and
R2D2 give each actor its own exploration rate for this reason; here the last envs of each
collector act as the evaluator does. Not in the MuZero or Dreamer papers: 0 is theirs.
"""
from __future__ import annotations

import numpy as np


def greedy_envs(fraction: float, envs: int) -> int:
    """How many of a collector's `envs` act greedily: round(fraction x envs), at least one
    when the fraction is positive (a share set on a small collector is not silently 0)."""
    return 0 if fraction <= 0 else max(1, min(envs, round(fraction * envs)))


def greedy_rows(fraction: float, envs: int) -> np.ndarray:
    """[envs] bool: True for the envs that act greedily (the last ones)."""
    rows = np.zeros(envs, bool)
    rows[envs - greedy_envs(fraction, envs):] = True
    return rows
