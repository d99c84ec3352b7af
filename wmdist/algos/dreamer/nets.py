"""Dreamer's networks: the shared world model (`wmdist.nets.world_model`) and the actor-critic."""
from __future__ import annotations

import copy

import torch
from torch import nn

from wmdist.algos.dreamer.actor import ActionDist
from wmdist.algos.dreamer.config import DreamerConfig
from wmdist.envs.spec import EnvSpec
from wmdist.nets.actions import action_to_env, action_to_model
from wmdist.nets.latent_layers import Heads, Latent
from wmdist.nets.polyak import polyak_
from wmdist.nets.world_model import WorldModel, head_width

__all__ = ["ActorCritic", "WorldModel", "action_to_env", "action_to_model"]


class ActorCritic(nn.Module):
    """Actor, critic and the slow critic (an EMA or periodic copy, never trained directly)."""

    def __init__(self, cfg: DreamerConfig, spec: EnvSpec, z_dim: int) -> None:
        super().__init__()
        self.cfg, self.spec = cfg, spec
        dims = {"h": cfg.deter, "z": z_dim}
        a_out = spec.num_actions if spec.discrete else 2 * spec.action_dim
        self.actor = Heads(dims, {"actor": a_out}, cfg.units, cfg.mlp_layers, cfg.act, cfg.norm)
        zero = ("critic",) if cfg.critic_head == "twohot" else ()
        self.critic = Heads(dims, {"critic": head_width(cfg.critic_head, cfg)}, cfg.units, cfg.mlp_layers, cfg.act, cfg.norm, zero_init=zero)
        self.slow_critic = copy.deepcopy(self.critic).requires_grad_(False)

    def policy(self, h: torch.Tensor, z: Latent) -> ActionDist:
        c = self.cfg
        out = self.actor({"h": h, "z": z})["actor"]
        return ActionDist(out, self.spec.discrete, c.actor_dist_cont, c.unimix, c.actor_min_std, c.actor_max_std,
                          c.actor_init_std)

    def update_slow(self, mix: float) -> None:
        polyak_(self.slow_critic, self.critic, mix, copy_buffers=False)
