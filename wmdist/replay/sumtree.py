"""Sum tree over a fixed number of slots: O(log N) vectorised update and prefix-sum search.

Leaves hold non-negative masses (p_i^alpha for prioritized replay, Schaul et al. 2016,
Sec. 3.3; 1 per occupied slot for uniform). The tree is one flat float64 array
`[2 * leaves]` with the root at index 1 and node i's children at 2i and 2i+1.
"""
from __future__ import annotations

import numpy as np


class SumTree:
    def __init__(self, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"SumTree capacity must be >= 1, got {capacity}")
        self.capacity = capacity
        self.leaves = 1 << max(0, (capacity - 1).bit_length())  # power of two >= capacity
        self.depth = self.leaves.bit_length() - 1
        self.tree = np.zeros(2 * self.leaves, dtype=np.float64)  # [2L]

    @property
    def total(self) -> float:
        return float(self.tree[1])

    def get(self, slots: np.ndarray) -> np.ndarray:
        return self.tree[self.leaves + np.asarray(slots, dtype=np.int64)]

    def values(self) -> np.ndarray:
        """Leaf masses [capacity] (a copy)."""
        return self.tree[self.leaves:self.leaves + self.capacity].copy()

    def set(self, slots: np.ndarray, masses: np.ndarray) -> None:
        """Set leaves `slots` [K] to `masses` [K] (last write wins on duplicates)."""
        slots = np.asarray(slots, dtype=np.int64).ravel()
        masses = np.asarray(masses, dtype=np.float64).ravel()
        if slots.size == 0:
            return
        if slots.min() < 0 or slots.max() >= self.capacity:
            raise ValueError(f"SumTree slot out of range [0, {self.capacity})")
        if not np.all(np.isfinite(masses)) or masses.min() < 0:
            raise ValueError("SumTree masses must be finite and >= 0")
        nodes = self.leaves + slots
        self.tree[nodes] = masses
        nodes = np.unique(nodes >> 1)
        while nodes[0] >= 1:  # recompute parents level by level from their children
            self.tree[nodes] = self.tree[2 * nodes] + self.tree[2 * nodes + 1]
            if nodes[0] == 1:
                break
            nodes = np.unique(nodes >> 1)

    def find(self, targets: np.ndarray) -> np.ndarray:
        """Slots whose prefix-sum interval holds each target in [0, total) -> [K] int64."""
        u = np.asarray(targets, dtype=np.float64).copy()
        node = np.ones(u.shape, dtype=np.int64)
        for _ in range(self.depth):
            left = 2 * node
            lm = self.tree[left]
            go_right = u >= lm
            u = np.where(go_right, u - lm, u)
            node = np.where(go_right, left + 1, left)
        slots = node - self.leaves
        # float round-off can land on a zero-mass leaf at the right edge: step back to a live one
        bad = (self.tree[node] <= 0) | (slots >= self.capacity)
        if bad.any():
            live = np.flatnonzero(self.tree[self.leaves:self.leaves + self.capacity] > 0)
            if live.size == 0:
                raise ValueError("SumTree is empty")
            pos = np.searchsorted(live, slots[bad], side="right") - 1
            slots[bad] = live[np.clip(pos, 0, live.size - 1)]
        return slots

    def sample(self, k: int, rng: np.random.Generator) -> np.ndarray:
        """k independent draws with P(slot) = mass / total -> [k] int64."""
        total = self.total
        if total <= 0:
            raise ValueError("cannot sample from an empty SumTree")
        return self.find(rng.random(k) * total)
