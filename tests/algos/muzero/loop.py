"""A small in-process actor-learner loop (no Ray) for MuZero tests: a VectorEnv, the
Policy, fixed-length windows cut per env the way replay stores them, uniform sampling
and the Learner, all in one process."""
from __future__ import annotations

import numpy as np

from wmdist.algos.base import Algorithm
from wmdist.envs.config import EnvConfig
from wmdist.envs.vector import make_vector_env


class InProcessLoop:
    def __init__(self, algo: Algorithm, env_cfg: EnvConfig, num_envs: int, seq_len: int, overlap: int,
                 seed: int = 0) -> None:
        self.algo = algo
        self.fields = algo.step_fields()
        self.venv = make_vector_env(env_cfg, num_envs, seed)
        self.policy = algo.make_policy()
        self.learner = algo.make_learner()
        self.version = 0
        self.policy.set_weights(self.learner.get_weights(), self.version)
        self.T, self.overlap = seq_len, overlap
        self.step = self.venv.reset()
        self.buffers: list[list[dict]] = [[] for _ in range(num_envs)]  # per env: records of the open window
        self.sequences: list[tuple[dict[str, np.ndarray], int]] = []  # (window [T, ...], real steps)
        self.returns: list[float] = []
        self.ep_return = np.zeros(num_envs)
        self.env_steps = 0
        self.rng = np.random.default_rng(seed)

    def _emit(self, i: int, last: bool) -> None:
        recs = self.buffers[i]
        window = {k: np.zeros((self.T, *s.shape), s.dtype) for k, s in self.fields.items()}
        for t, rec in enumerate(recs):
            for k in window:
                window[k][t] = rec[k]
        self.sequences.append((window, len(recs)))
        self.buffers[i] = [] if last else recs[self.T - self.overlap:]

    def collect(self, steps: int, explore: bool = True) -> None:
        e = self.venv.num_envs
        for _ in range(steps):
            s = self.step
            self.policy.set_progress(self.env_steps, getattr(self.learner, "updates", 0))
            actions, extras = self.policy.act(s.obs, s.first, s.legal, s.to_play, explore)
            nxt = self.venv.step(actions)
            self.ep_return += nxt.reward
            for i in range(e):
                rec = {"obs": s.obs[i], "action": actions[i], "reward": s.reward[i], "first": s.first[i],
                       "last": False, "terminal": False, **{k: v[i] for k, v in extras.items()}}
                self.buffers[i].append(rec)
                if len(self.buffers[i]) == self.T:
                    self._emit(i, last=False)
                if nxt.terminated[i] or nxt.truncated[i]:
                    final = {k: np.zeros_like(v) for k, v in rec.items()}
                    final.update(obs=nxt.final_obs[i], reward=nxt.reward[i], first=False, last=True,
                                 terminal=bool(nxt.terminated[i]))
                    self.buffers[i].append(final)
                    self._emit(i, last=True)
                    self.returns.append(float(self.ep_return[i]))
                    self.ep_return[i] = 0.0
            self.step = nxt
            self.env_steps += e

    def sample(self, batch_size: int) -> dict[str, np.ndarray]:
        idx = self.rng.integers(0, len(self.sequences), size=batch_size)
        batch = {k: np.stack([self.sequences[j][0][k] for j in idx]) for k in self.fields}
        batch["mask"] = np.stack([np.arange(self.T) < self.sequences[j][1] for j in idx])
        batch["is_weight"] = np.ones(batch_size, np.float32)
        return batch

    def train(self, updates: int, batch_size: int) -> list[dict[str, float]]:
        metrics = [self.learner.update(self.sample(batch_size)).metrics for _ in range(updates)]
        self.version += 1
        self.policy.set_weights(self.learner.get_weights(), self.version)
        return metrics
