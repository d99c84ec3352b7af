"""Root noise (Dirichlet for pUCT, Gumbel for Gumbel MuZero) and the sequential-halving schedule."""
from __future__ import annotations

import math

import numpy as np


def sample_root_noise(
    rng: np.random.Generator, legal: np.ndarray, alpha: float, gumbel: bool, add_noise: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Return (dirichlet [B, A], gumbel [B, A]) float64 drawn in a fixed order.

    Dirichlet: one draw per row over its legal actions (zeros elsewhere); only drawn in
    pUCT mode with add_noise. Gumbel(0, 1): one [B, A] draw, only in Gumbel mode with
    add_noise. Tests rebuild the same noise from the same seed.
    """
    batch, num_actions = legal.shape
    dirichlet = np.zeros((batch, num_actions))
    g = np.zeros((batch, num_actions))
    if not add_noise:
        return dirichlet, g
    if gumbel:
        g = rng.gumbel(size=(batch, num_actions))
        return dirichlet, g
    for b in range(batch):
        idx = np.flatnonzero(legal[b])
        dirichlet[b, idx] = rng.dirichlet(np.full(len(idx), alpha))
    return dirichlet, g


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


def considered_visit_table(max_considered: int, num_simulations: int) -> np.ndarray:
    """[max_considered + 1, num_simulations] int32: row m is the schedule for m actions."""
    table = np.zeros((max_considered + 1, num_simulations), dtype=np.int32)
    for m in range(max_considered + 1):
        table[m] = considered_visit_sequence(m, num_simulations)
    return table
