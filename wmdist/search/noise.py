"""Root noise (Dirichlet for pUCT, Gumbel for Gumbel MuZero) and the sequential-halving schedule."""
from __future__ import annotations

import functools
import math

import numpy as np


def sample_root_noise(
    rng: np.random.Generator, legal: np.ndarray, alpha: float, gumbel: bool, add_noise: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Return (dirichlet [B, A], gumbel [B, A]) float64 drawn in a fixed order.

    Dirichlet(alpha) over each row's legal actions (zeros elsewhere), drawn for the whole
    batch at once as normalised Gamma(alpha, 1) variables (the Dirichlet's definition); only
    in pUCT mode with add_noise. Gumbel(0, 1): one [B, A] draw, only in Gumbel mode with
    add_noise. Tests rebuild the same noise from the same seed.
    """
    batch, num_actions = legal.shape
    zeros = np.zeros((batch, num_actions))
    if not add_noise:
        return zeros, zeros
    if gumbel:
        return zeros, rng.gumbel(size=(batch, num_actions))
    gammas = rng.gamma(alpha, size=(batch, num_actions)) * legal
    total = gammas.sum(axis=1, keepdims=True)
    # Tiny alpha can underflow every gamma of a row to 0: fall back to uniform there.
    gammas = np.where(total > 0, gammas, legal.astype(np.float64))
    return gammas / gammas.sum(axis=1, keepdims=True), zeros


def considered_visit_sequence(num_considered: int, num_simulations: int) -> list[int]:
    """Sequential halving (Gumbel MuZero, Karnin et al. 2013) as a per-simulation schedule.

    Entry s is the visit count that the root action picked at simulation s must have: the
    budget is split over ceil(log2 m) phases; in each phase every remaining action gets
    max(1, floor(n / (phases * remaining))) more visits, then the remaining set halves
    (never below 2). Picking, at simulation s, the best-scoring action whose count equals
    entry s visits the top half of the previous phase, so the schedule alone implements
    Gumbel-top-k (phase 1, all counts 0) and the halving.
    """
    if num_considered <= 1:
        return list(range(num_simulations))
    phases = math.ceil(math.log2(num_considered))
    sequence: list[int] = []
    remaining = num_considered
    visits_each = 0  # every action still in the running has this many visits
    while len(sequence) < num_simulations:
        per_action = max(1, num_simulations // (phases * remaining))
        for _ in range(per_action):
            sequence.extend([visits_each] * remaining)
            visits_each += 1
        remaining = max(2, remaining // 2)
    return sequence[:num_simulations]


@functools.lru_cache(maxsize=64)
def considered_visit_table(max_considered: int, num_simulations: int) -> np.ndarray:
    """[max_considered + 1, num_simulations] int32: row m is the schedule for m actions (read-only, cached)."""
    table = np.zeros((max_considered + 1, num_simulations), dtype=np.int32)
    for m in range(max_considered + 1):
        table[m] = considered_visit_sequence(m, num_simulations)
    table.setflags(write=False)
    return table
