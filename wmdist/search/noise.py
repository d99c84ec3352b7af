"""Root noise (Dirichlet for pUCT, Gumbel for Gumbel MuZero) and the sequential-halving schedule."""
from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit


def draw_root_noise(
    rng: np.random.Generator, batch: int, num_actions: int, alpha: float, gumbel: bool, add_noise: bool
) -> np.ndarray | None:
    """The root noise's random draws [B, A] float64, or None without noise.

    pUCT: Gamma(alpha, 1) variables for every (row, action), turned into the Dirichlet by
    `dirichlet_row` (a Dirichlet is normalised Gammas). Gumbel mode: Gumbel(0, 1). One
    draw of the whole batch, so a seed fixes the noise of every row.
    """
    if not add_noise:
        return None
    if gumbel:
        return rng.gumbel(size=(batch, num_actions))
    return rng.gamma(alpha, size=(batch, num_actions))


@njit(cache=True, error_model="numpy")
def dirichlet_row(gammas, legal, out):
    """out [A] = Dirichlet sample over the legal actions (legal != 0) from one row of Gammas.

    Tiny alpha can underflow every Gamma of a row to 0: the row falls back to uniform.
    """
    total = 0.0
    num_legal = 0
    for a in range(gammas.shape[0]):
        if legal[a] != 0:
            total += gammas[a]
            num_legal += 1
    for a in range(gammas.shape[0]):
        if legal[a] == 0:
            out[a] = 0.0
        elif total > 0.0:
            out[a] = gammas[a] / total
        else:
            out[a] = 1.0 / num_legal


def sample_root_noise(
    rng: np.random.Generator, legal: np.ndarray, alpha: float, gumbel: bool, add_noise: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Return (dirichlet [B, A], gumbel [B, A]) float64: exactly the root noise that
    `search` uses with the same rng state (tests hand it to the reference search).

    Dirichlet(alpha) over each row's legal actions (zeros elsewhere), only in pUCT mode with
    add_noise; Gumbel(0, 1) only in Gumbel mode with add_noise; zeros otherwise.
    """
    batch, num_actions = legal.shape
    draws = draw_root_noise(rng, batch, num_actions, alpha, gumbel, add_noise)
    zeros = np.zeros((batch, num_actions))
    if draws is None:
        return zeros, zeros
    if gumbel:
        return zeros, draws
    dirichlet = np.zeros((batch, num_actions))
    for b in range(batch):
        dirichlet_row(draws[b], legal[b].astype(np.int32), dirichlet[b])
    return dirichlet, zeros


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
