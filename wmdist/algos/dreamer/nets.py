"""Dreamer's networks: the world model (encoder, RSSM, heads) and the actor-critic."""
from __future__ import annotations

import copy

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from wmdist.algos.dreamer.actor import ActionDist
from wmdist.algos.dreamer.config import DreamerConfig
from wmdist.algos.dreamer.layers import Heads, Latent
from wmdist.algos.dreamer.rssm import RSSM
from wmdist.envs.spec import EnvSpec
from wmdist.nets.conv import ConvDecoder, ConvEncoder
from wmdist.nets.dists import symlog
from wmdist.nets.mlp import mlp


def head_width(kind: str, cfg: DreamerConfig) -> int:
    return cfg.bins if kind == "twohot" else 1


class WorldModel(nn.Module):
    """Encoder + RSSM + reward / continue / decoder heads (cfg must be `resolved()`)."""

    def __init__(self, cfg: DreamerConfig, spec: EnvSpec) -> None:
        super().__init__()
        self.cfg, self.spec = cfg, spec
        self.image = spec.obs_kind == "image"
        if self.image:
            if tuple(spec.obs_shape[:2]) != (64, 64):
                raise ValueError(f"Dreamer's CNN needs 64x64 images, got obs_shape {spec.obs_shape}")
            self.encoder: nn.Module = ConvEncoder(spec.obs_shape[2], cfg.cnn_depth, cfg.act, cfg.norm)
            embed_dim = self.encoder.out_dim
        else:
            if len(spec.obs_shape) != 1:
                raise ValueError(f"Dreamer's vector encoder needs obs_shape (D,), got {spec.obs_shape}")
            self.encoder = mlp(spec.obs_shape[0], [cfg.units] * cfg.mlp_layers, None, cfg.act, cfg.norm)
            embed_dim = cfg.units
        self.rssm = RSSM(cfg, embed_dim, spec.action_dim)
        dims = {"h": cfg.deter, "z": self.rssm.z_dim}
        heads = {"reward": head_width(cfg.reward_head, cfg)}
        if cfg.cont_head:
            heads["cont"] = 1
        if not self.image:
            heads["decoder"] = spec.obs_shape[0]
        zero = ("reward",) if cfg.reward_head == "twohot" else ()
        self.heads = Heads(dims, heads, cfg.units, cfg.mlp_layers, cfg.act, cfg.norm, zero_init=zero)
        self.last_head = "cont" if cfg.cont_head else "reward"  # heads needed in imagination
        if self.image:
            self.image_decoder = ConvDecoder(cfg.deter + self.rssm.z_dim, spec.obs_shape[2], cfg.cnn_depth, cfg.act, cfg.norm)

    def encode(self, obs: torch.Tensor) -> torch.Tensor:
        """[..., *obs_shape] -> [..., E]."""
        if self.image:
            return self.encoder(obs)
        x = obs.float()
        return self.encoder(symlog(x) if self.cfg.symlog_inputs else x)

    def obs_target(self, obs: torch.Tensor) -> torch.Tensor:
        """What the decoder regresses: symlog(obs) (V3 vectors), obs, or pixels in [-0.5, 0.5]."""
        if self.image:
            return obs.float() / 255.0 - 0.5
        x = obs.float()
        return symlog(x) if self.cfg.symlog_targets else x

    def decode(self, h: torch.Tensor, z: Latent, head_out: dict[str, torch.Tensor] | None = None) -> torch.Tensor:
        """Predicted observation target for states [N] -> [N, *obs_shape] (in `obs_target` space)."""
        if self.image:
            return self.image_decoder(torch.cat([h, z.dense()], -1))
        if head_out is None:
            head_out = self.heads({"h": h, "z": z})
        return head_out["decoder"]


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

    @torch.no_grad()
    def update_slow(self, mix: float) -> None:
        for slow, fast in zip(self.slow_critic.parameters(), self.critic.parameters()):
            slow.lerp_(fast, mix)


# --- actions: env space <-> model space --------------------------------------------------
def action_to_model(action: torch.Tensor, spec: EnvSpec) -> torch.Tensor:
    """Stored actions [..] or [.., D] -> model input [.., A]: one-hot, or rescaled to [-1, 1]."""
    if spec.discrete:
        return F.one_hot(action.long().clamp(0, spec.num_actions - 1), spec.num_actions).float()
    lo, hi = _bounds(spec)
    low = torch.as_tensor(lo, device=action.device)
    high = torch.as_tensor(hi, device=action.device)
    return (2 * (action.float() - low) / (high - low) - 1).clamp(-1, 1)


def action_to_env(action: torch.Tensor, spec: EnvSpec) -> np.ndarray:
    """Model actions (indices [E], or [E, D] in [-1, 1]) -> env actions of the spec's dtype."""
    if spec.discrete:
        return action.long().cpu().numpy().astype(np.int64)
    low, high = _bounds(spec)
    a = np.clip(action.detach().float().cpu().numpy(), -1, 1)
    return (low + (a + 1) * 0.5 * (high - low)).astype(np.float32).reshape(-1, *spec.action_shape)


def _bounds(spec: EnvSpec) -> tuple[np.ndarray, np.ndarray]:
    """Action bounds [D] (a spec without bounds means [-1, 1])."""
    d = spec.action_dim
    low = np.asarray(spec.action_low or (-1.0,) * d, np.float32).reshape(-1)
    high = np.asarray(spec.action_high or (1.0,) * d, np.float32).reshape(-1)
    return low, high
