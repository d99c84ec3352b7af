"""The in-process loop MuZero tests use: the local runner's own collector, replay and
learner (`wmdist.runtime.local.LocalSession`), so tests see exactly what a run stores."""
from __future__ import annotations

import numpy as np

from tests.algos.local_config import local_run_config
from wmdist.algos.base import Algorithm
from wmdist.envs.config import EnvConfig
from wmdist.runtime.local import LocalSession


class InProcessLoop:
    def __init__(self, algo: Algorithm, env_cfg: EnvConfig, num_envs: int, seq_len: int, overlap: int,
                 seed: int = 0) -> None:
        self.session = LocalSession(local_run_config(algo, env_cfg, num_envs, seq_len, overlap, seed))

    @property
    def learner(self):
        return self.session.learner

    @property
    def policy(self):
        return self.session.policy

    @property
    def env_steps(self) -> int:
        return self.session.env_steps

    @property
    def returns(self) -> list[float]:
        return self.session.returns

    @property
    def sequences(self) -> list[tuple[dict[str, np.ndarray], int]]:
        """Every stored window and its real steps, in insert order."""
        return self.session.stored()

    def collect(self, steps: int, explore: bool = True) -> None:
        self.session.collect(steps, explore)

    def sample(self, batch_size: int) -> dict[str, np.ndarray]:
        return self.session.sample(batch_size)

    def train(self, updates: int, batch_size: int) -> list[dict[str, float]]:
        return self.session.train(updates, batch_size)
