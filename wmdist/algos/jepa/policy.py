"""JEPA's acting policy.

Collecting (explore=True): reward-free exploration data, uniform random actions, each step
keeping the previous one with probability `explore_keep` (straight runs that cross rooms);
no model is used. Evaluating (explore=False): embed the frame and the goal image, then plan
toward the goal with CEM at every step (MPC, the plan's first action is taken), for all E
envs in one batched call; with a transition graph in the weights (`graph_pairs`), toward
a waypoint on the graph's shortest path to the goal (`waypoints.py`). Planning with weights
that no update produced is refused.
"""
from __future__ import annotations

import numpy as np
import torch

from wmdist.algos.base import Policy, Weights
from wmdist.algos.jepa.config import JepaConfig
from wmdist.algos.jepa.model import GRAPH_KEY, JepaModel, load_model
from wmdist.algos.jepa.planning import goal_distance_fn
from wmdist.algos.jepa.waypoints import TransitionGraph
from wmdist.envs.spec import EnvSpec
from wmdist.nets.actions import action_to_env
from wmdist.nets.generator import seeded_generator
from wmdist.search.cem import cem_plan, shift_plan

OBS_SHAPE = (64, 64, 6)  # the current frame and the goal image, 3 channels each


def check_obs(obs: np.ndarray) -> None:
    """One-line ValueError unless obs is [E, 64, 64, 6] uint8."""
    if obs.ndim != 4 or tuple(obs.shape[1:]) != OBS_SHAPE:
        raise ValueError(f"jepa: observations must be [E, 64, 64, 6] (a 64x64 frame and its goal image, 3 channels "
                         f"each), got {list(obs.shape)}")


class JepaPolicy(Policy):
    """Carries per env the last h embeddings, the h - 1 actions between them and the last plan."""

    def __init__(self, cfg: JepaConfig, spec: EnvSpec, device: str = "cpu", seed: int = 0) -> None:
        self.cfg, self.spec, self.device = cfg, spec, torch.device(device)
        self.model = JepaModel(cfg, spec.action_dim).to(self.device).eval()
        self.generator = seeded_generator(self.device, seed)
        self.rng = np.random.default_rng(seed)
        self.version, self.trained_updates = -1, 0
        self.z_hist: torch.Tensor | None = None  # [E, h, D]
        self.a_past: torch.Tensor | None = None  # [E, h-1, A]
        self.plan: torch.Tensor | None = None  # [E, H, A]
        self.plan_from: tuple[torch.Tensor, torch.Tensor] | None = None  # the last plan's (z_hist, a_past)
        self.explore_action: np.ndarray | None = None  # [E, A] model space
        self.graph_nodes: np.ndarray | None = None  # [2P, D] the published transitions' embeddings
        self.graph: TransitionGraph | None = None  # built from them at the first plan (collectors never need it)

    def set_weights(self, weights: Weights, version: int) -> None:
        self.trained_updates = load_model(self.model, weights)
        self.version = version
        self.graph_nodes = np.asarray(weights[GRAPH_KEY]) if GRAPH_KEY in weights else None
        self.graph = None

    def _explore(self, e: int, first: np.ndarray) -> np.ndarray:
        a_dim = self.spec.action_dim
        fresh = self.rng.uniform(-1, 1, (e, a_dim)).astype(np.float32)
        if self.explore_action is None or self.explore_action.shape[0] != e:
            self.explore_action = fresh
        keep = (self.rng.uniform(size=e) < self.cfg.explore_keep) & ~np.asarray(first, bool)  # [E]
        self.explore_action = np.where(keep[:, None], self.explore_action, fresh)
        return action_to_env(torch.as_tensor(self.explore_action), self.spec)

    @torch.no_grad()
    def act(self, obs, first, legal, to_play, explore):  # type: ignore[override]
        obs = np.asarray(obs)
        check_obs(obs)
        e = obs.shape[0]
        if explore:
            return self._explore(e, first), {}
        if self.trained_updates <= 0:
            raise ValueError(f"jepa: cannot plan to a goal before any training (weights v{self.version} come from "
                             "0 learner updates)")
        z, z_goal = self.model.encode_obs(torch.as_tensor(obs, device=self.device))  # [E, D] each
        if self.graph_nodes is not None:  # a far goal: plan toward a waypoint on the replay graph instead
            if self.graph is None:
                self.graph = TransitionGraph(self.graph_nodes, self.cfg.graph_knn, self.cfg.graph_link)
            z_goal = self.graph.waypoints(z, z_goal, self.cfg.waypoint_steps)
        h, a_dim = self.cfg.history, self.spec.action_dim
        restart = torch.as_tensor(np.asarray(first, bool), device=self.device)  # [E]
        if self.z_hist is None or self.z_hist.shape[0] != e:
            self.z_hist = z[:, None].repeat(1, h, 1)
            self.a_past = torch.zeros(e, h - 1, a_dim, device=self.device)
            self.plan = None
            restart = torch.ones_like(restart)
        assert self.a_past is not None
        # a new episode's history is its first embedding repeated, with no past actions
        self.z_hist = torch.where(restart[:, None, None], z[:, None].expand(-1, h, -1),
                                  torch.cat([self.z_hist[:, 1:], z[:, None]], 1))
        self.a_past = torch.where(restart[:, None, None], torch.zeros_like(self.a_past), self.a_past)
        low = torch.full((e, a_dim), -1.0, device=self.device)  # model space: the bounds map to [-1, 1]
        high = torch.ones_like(low)
        init = None
        if self.cfg.planner.warm_start and self.plan is not None:
            init = shift_plan(self.plan, low, high)
            init[restart] = 0.0
        score = goal_distance_fn(self.model, self.z_hist, self.a_past, z_goal, self.cfg.goal_cost, self.cfg.step_cost)
        result = cem_plan(score, low, high, self.cfg.planner, self.generator, init)
        action = result.action  # [E, A]
        self.plan, self.plan_from = result.mean, (self.z_hist, self.a_past)
        if h > 1:
            self.a_past = torch.cat([self.a_past[:, 1:], action[:, None]], 1)
        return action_to_env(action, self.spec), {}
