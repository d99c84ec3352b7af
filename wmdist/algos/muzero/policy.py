"""MuZeroPolicy: E envs searched together in one batched MCTS call per step."""
from __future__ import annotations

import numpy as np

from wmdist.algos.base import Policy
from wmdist.algos.greedy_share import greedy_rows
from wmdist.algos.muzero.config import MuZeroConfig
from wmdist.algos.muzero.networks import MuZeroNet
from wmdist.algos.muzero.searching import SearchingRole
from wmdist.envs.spec import EnvSpec


def temperature_at(cfg: MuZeroConfig, env_steps: int) -> float:
    """Visit-count temperature for this many env steps (paper Atari: 1, 0.5, 0.25 in turn)."""
    i = int(np.searchsorted(np.asarray(cfg.temperature_env_steps), env_steps, side="right"))
    return float(cfg.visit_temperatures[i])


def select_actions(counts: np.ndarray, temperatures: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Sample a ~ N(a)^(1/T) per row ([B, A] counts, [B] temperatures); T = 0 is argmax."""
    actions = counts.argmax(-1)
    hot = temperatures > 0
    if hot.any():
        c = counts[hot].astype(np.float64)
        logp = np.where(c > 0, np.log(np.maximum(c, 1e-12)), -np.inf) / temperatures[hot, None]
        p = np.exp(logp - logp.max(-1, keepdims=True))
        p /= p.sum(-1, keepdims=True)
        u = rng.random(len(p))[:, None]
        actions[hot] = np.minimum((p.cumsum(-1) < u).sum(-1), counts.shape[1] - 1)
    return actions.astype(np.int64)


class MuZeroPolicy(SearchingRole, Policy):
    def __init__(self, net: MuZeroNet, cfg: MuZeroConfig, spec: EnvSpec, seed: int, device: str = "cpu") -> None:
        self._init_search(net, cfg, spec, seed, device)
        self.env_steps = 0
        self.moves: np.ndarray | None = None  # [E] moves played in each env's current episode
        self.last_net_seconds = 0.0
        self.last_search_seconds = 0.0

    def set_progress(self, env_steps: int, updates: int) -> None:
        self.env_steps = int(env_steps)

    def _temperatures(self, first: np.ndarray) -> np.ndarray:
        e = len(first)
        if self.moves is None or len(self.moves) != e:
            self.moves = np.zeros(e, np.int64)
        self.moves[first.astype(bool)] = 0
        if self.cfg.temperature_moves > 0:  # board games: explore the opening, then play greedily
            temps = np.where(self.moves < self.cfg.temperature_moves, 1.0, 0.0)
        else:
            temps = np.full(e, temperature_at(self.cfg, self.env_steps))
        temps[greedy_rows(self.cfg.greedy_fraction, e)] = 0.0  # the last envs act greedily
        self.moves += 1
        return temps

    def act(self, obs, first, legal, to_play, explore):
        e = obs.shape[0]
        if obs.shape[1:] != tuple(self.spec.obs_shape):
            raise ValueError(f"muzero policy: obs shape {obs.shape[1:]} != env spec {tuple(self.spec.obs_shape)}")
        a = self.spec.num_actions
        legal_m = np.ones((e, a), bool) if legal is None else np.asarray(legal, bool)
        players = None if not self.two_player or to_play is None else np.asarray(to_play, np.int64)
        temps = self._temperatures(np.asarray(first)) if explore else np.zeros(e)
        res = self.searcher.run(obs, legal_m, players, self.rng, add_noise=explore,
                                temperature=float(temps.max()) if explore else 0.0)
        if self.cfg.search.gumbel:
            actions = res.action.astype(np.int64)  # sequential halving already chose (noise-free when greedy)
        else:
            actions = select_actions(res.visit_counts, temps, self.rng)
        self.last_net_seconds, self.last_search_seconds = res.net_seconds, res.total_seconds
        extras = {"search_policy": res.policy_target, "search_value": res.root_value}
        if self.two_player:
            extras["legal"] = legal_m
            extras["to_play"] = (np.zeros(e) if to_play is None else np.asarray(to_play)).astype(np.int8)
        return actions, extras
