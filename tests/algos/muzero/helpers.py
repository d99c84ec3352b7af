"""Random stored-sequence batches shaped like replay's samples (for target and loss tests)."""
from __future__ import annotations

import numpy as np


def random_batch(rng: np.random.Generator, b: int, t: int, a: int, obs_dim: int = 3) -> dict[str, np.ndarray]:
    """Rows are windows of one episode: some end in a terminal or truncated last step then
    padding, some run to the window's end; some start an episode, some continue one."""
    mask = np.zeros((b, t), bool)
    last = np.zeros((b, t), bool)
    terminal = np.zeros((b, t), bool)
    first = np.zeros((b, t), bool)
    for i in range(b):
        kind = rng.integers(3)  # 0 terminal end, 1 truncated end, 2 no end in the window
        length = t if kind == 2 else int(rng.integers(2, t + 1))
        mask[i, :length] = True
        if kind < 2:
            last[i, length - 1] = True
            terminal[i, length - 1] = kind == 0
        first[i, 0] = bool(rng.integers(2))
    reward = (rng.normal(size=(b, t)) * mask).astype(np.float32)
    reward[first] = 0.0
    acting = mask & ~last
    sp = rng.dirichlet(np.ones(a), size=(b, t)).astype(np.float32) * acting[..., None]
    sv = (rng.normal(size=(b, t)) * 5 * acting).astype(np.float32)
    action = (rng.integers(0, a, size=(b, t)) * acting).astype(np.int64)
    obs = (rng.normal(size=(b, t, obs_dim)) * mask[..., None]).astype(np.float32)
    return {
        "obs": obs, "action": action, "reward": reward, "first": first, "last": last, "terminal": terminal,
        "search_policy": sp, "search_value": sv, "mask": mask, "is_weight": np.ones(b, np.float32),
    }
