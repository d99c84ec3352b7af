"""VectorEnv: E environments stepped together in one process, with same-step auto-reset.

When env i's episode ends on a step, the returned `obs[i]` is already the first
observation of its next episode (`first[i] = True`) and the ended episode's last
observation is in `final_obs[i]`; `reward`, `terminated`, `truncated` belong to the step
just taken. Seeding: env i uses `seed + i`, so one seed gives one trajectory.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from wmdist.envs.config import EnvConfig
from wmdist.envs.env import Env
from wmdist.envs.spec import EnvSpec


@dataclass
class VecStep:
    obs: np.ndarray  # [E, *obs_shape] (already the new episode's first obs where an episode ended)
    reward: np.ndarray  # [E] float32 reward of the step just taken (0 after reset())
    terminated: np.ndarray  # [E] bool
    truncated: np.ndarray  # [E] bool
    final_obs: np.ndarray  # [E, *obs_shape] last obs of the ended episode where terminated|truncated, else == obs
    first: np.ndarray  # [E] bool: obs starts an episode (all True after reset(); True where auto-reset happened)
    legal: np.ndarray | None  # [E, A] bool for obs (discrete envs), else None
    to_play: np.ndarray | None  # [E] int for obs (2-player games), else None


class VectorEnv:
    """Either `VectorEnv(env_fns, seed=s)` or `VectorEnv(cfg=cfg, num_envs=E, seed=s)`."""

    def __init__(
        self,
        env_fns: Sequence[Callable[[], Env]] | None = None,
        *,
        cfg: EnvConfig | None = None,
        num_envs: int | None = None,
        seed: int = 0,
    ) -> None:
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ValueError(f"VectorEnv seed must be an int >= 0, got {seed!r}")
        if (env_fns is None) == (cfg is None):
            raise ValueError("VectorEnv needs either env_fns or (cfg, num_envs), not both")
        if env_fns is not None:
            if num_envs is not None and num_envs != len(env_fns):
                raise ValueError(f"num_envs={num_envs} but {len(env_fns)} env_fns given")
            self.envs: list[Env] = [fn() for fn in env_fns]
        else:
            if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
                raise ValueError(f"VectorEnv num_envs must be an int >= 1, got {num_envs!r}")
            from wmdist.envs.factory import make_env

            self.envs = []
            try:
                for i in range(num_envs):
                    self.envs.append(make_env(cfg, seed + i))
            except BaseException:
                self.close()
                raise
        if not self.envs:
            raise ValueError("VectorEnv needs at least one env")
        self.spec: EnvSpec = self.envs[0].spec
        for e in self.envs[1:]:
            if e.spec != self.spec:
                raise ValueError(f"VectorEnv envs differ: {e.spec} vs {self.spec}")
        self.num_envs = len(self.envs)
        self._seed: int | None = seed  # used by the first reset() unless one is given
        self._needs_reset = True
        self._legal: np.ndarray | None = None  # [E, A] mask of the last returned obs

    def reset(self, seed: int | None = None) -> VecStep:
        """Start a new episode in every env (env i with `seed + i` when seeded)."""
        if seed is None:
            seed = self._seed
        self._seed = None
        obs = self._stack([e.reset(None if seed is None else seed + i) for i, e in enumerate(self.envs)])
        self._needs_reset = False
        E = self.num_envs
        return self._pack(obs, np.zeros(E, np.float32), np.zeros(E, bool), np.zeros(E, bool), obs.copy(), np.ones(E, bool))

    def step(self, actions: np.ndarray) -> VecStep:
        """Step every env with its action (`actions[i]`); auto-reset envs whose episode ended."""
        if self._needs_reset:
            raise RuntimeError("VectorEnv.step called before reset()")
        actions = np.asarray(actions)
        want = (self.num_envs, *self.spec.action_shape)
        if actions.shape != want:
            raise ValueError(f"actions must have shape {want}, got {actions.shape}")
        if self._legal is not None:
            self._check_legal(actions)  # before stepping any env, so a bad batch changes nothing
        obs_list, rewards, terms, truncs, ended = [], [], [], [], []
        for i, env in enumerate(self.envs):
            o, r, term, trunc = env.step(actions[i])
            rewards.append(r)
            terms.append(term)
            truncs.append(trunc)
            if term or trunc:
                ended.append((i, o))
                o = env.reset()  # same-step auto-reset; the env continues its seeded stream
            obs_list.append(o)
        obs = self._stack(obs_list)  # [E, *obs_shape]
        final_obs = obs.copy()
        first = np.zeros(self.num_envs, bool)
        for i, o in ended:
            final_obs[i] = o
            first[i] = True
        return self._pack(
            obs, np.asarray(rewards, np.float32), np.asarray(terms, bool), np.asarray(truncs, bool), final_obs, first
        )

    def _check_legal(self, actions: np.ndarray) -> None:
        n = self.spec.num_actions
        if actions.dtype.kind not in "iu":
            raise ValueError(f"discrete actions must be integers, got dtype {actions.dtype}")
        bad = np.flatnonzero((actions < 0) | (actions >= n))
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"action {int(actions[i])} of env {i} out of range [0, {n}); no env was stepped")
        bad = np.flatnonzero(~self._legal[np.arange(self.num_envs), actions])
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"illegal action {int(actions[i])} for env {i} (not in its legal mask); no env was stepped")

    def _stack(self, rows: list[np.ndarray]) -> np.ndarray:
        # Row assignment into a preallocated array: cheaper than np.stack for small rows.
        out = np.empty((self.num_envs, *self.spec.obs_shape), self.spec.obs_dtype)
        for i, row in enumerate(rows):
            out[i] = row
        return out

    def _pack(self, obs, reward, terminated, truncated, final_obs, first) -> VecStep:
        legal = None
        if self.spec.discrete:
            legal = np.empty((self.num_envs, self.spec.num_actions), bool)  # [E, A]
            for i, e in enumerate(self.envs):
                legal[i] = e.legal_actions()
        to_play = np.array([e.to_play() for e in self.envs], np.int64) if self.spec.players > 1 else None
        self._legal = legal
        return VecStep(obs, reward, terminated, truncated, final_obs, first, legal, to_play)

    def render(self, index: int = 0) -> np.ndarray:
        """RGB frame of env `index` (for videos)."""
        return self.envs[index].render()

    def close(self) -> None:
        for e in getattr(self, "envs", []):
            e.close()


def make_vector_env(cfg: EnvConfig, num_envs: int, seed: int) -> VectorEnv:
    """E copies of `cfg`'s env, env i seeded with `seed + i`."""
    return VectorEnv(cfg=cfg, num_envs=num_envs, seed=seed)
