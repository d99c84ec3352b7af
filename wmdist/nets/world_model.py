"""A reconstructive RSSM world model: encoder, RSSM, reward / continue / decoder heads.

PlaNet's model, kept by Dreamer V1-V3 (each version changes sizes, heads and the latent);
PlaNet and Dreamer both build it from their configs.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
import torch
from torch import nn

from wmdist.envs.spec import EnvSpec
from wmdist.nets.conv import ConvDecoder, ConvEncoder
from wmdist.nets.dists import symexp, symlog
from wmdist.nets.latent_layers import Heads, Latent
from wmdist.nets.mlp import mlp
from wmdist.nets.rssm import RSSM, RSSMConfig, RSSMSettings

Weights = dict[str, np.ndarray]  # as `wmdist.algos.base.Weights` (nets does not import algos)


class WorldModelConfig(RSSMConfig, Protocol):
    """The fields the world model reads beyond the RSSM's."""

    mlp_layers: int  # hidden layers of the vector encoder and of every head
    cnn_depth: int  # channels of the first conv layer (64x64 images)
    symlog_inputs: bool  # symlog vector observations before the encoder
    symlog_targets: bool  # the vector decoder predicts symlog(obs)
    reward_head: str  # "mse" (unit Gaussian) or "twohot"
    bins: int  # two-hot bins (reward_head "twohot")
    cont_head: bool  # learn a continue head


def check_spec(spec: EnvSpec, who: str) -> None:
    """One-line ValueError unless `spec` suits the world model: one player, flat vectors or 64x64 images."""
    if spec.players != 1:
        raise ValueError(f"{who} supports single-player envs only, {spec.id} has {spec.players} players")
    if spec.obs_kind == "image" and tuple(spec.obs_shape[:2]) != (64, 64):
        raise ValueError(f"{who} needs 64x64 image observations, {spec.id} gives {spec.obs_shape}")
    if spec.obs_kind == "vector" and len(spec.obs_shape) != 1:
        raise ValueError(f"{who} needs flat vector observations, {spec.id} gives {spec.obs_shape}")
    if spec.obs_kind not in ("vector", "image"):
        raise ValueError(f"unknown obs_kind {spec.obs_kind!r} for {spec.id}")


def head_width(kind: str, cfg: WorldModelConfig) -> int:
    return cfg.bins if kind == "twohot" else 1


class WorldModel(nn.Module):
    """Encoder + RSSM + reward / continue / decoder heads (cfg: a resolved `DreamerConfig` or PlaNet's settings)."""

    def __init__(self, cfg: WorldModelConfig, spec: EnvSpec) -> None:
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

    def target_to_obs(self, pred: torch.Tensor) -> torch.Tensor:
        """The inverse of `obs_target` for decoder outputs: observations in their own units (float),
        pixels in [0, 1] (clamped)."""
        pred = pred.float()
        if self.image:
            return (pred + 0.5).clamp(0, 1)
        return symexp(pred) if self.cfg.symlog_targets else pred

    def filter_step(
        self,
        h: torch.Tensor,  # [E, D] h_{t-1}
        z: Latent,  # [E] z_{t-1}
        prev_action: torch.Tensor,  # [E, A] a_{t-1}, model space
        obs: torch.Tensor,  # [E, *obs_shape] o_t
        keep: torch.Tensor,  # [E, 1] 0 where o_t starts an episode (the state restarts)
        generator: torch.Generator | None = None,
    ) -> tuple[torch.Tensor, Latent]:
        """One acting step of the posterior: h_t, then z_t ~ q(z_t | h_t, o_t), without gradients."""
        rssm = self.rssm
        h = rssm.img_step(h, z, rssm.action_part(prev_action), keep)
        post = rssm.post(h, rssm.embed_part(self.encode(obs)))
        return h, rssm.sample(post, generator, grad=False)

    def decode(self, h: torch.Tensor, z: Latent, head_out: dict[str, torch.Tensor] | None = None) -> torch.Tensor:
        """Predicted observation target for states [N] -> [N, *obs_shape] (in `obs_target` space)."""
        if self.image:
            return self.image_decoder(torch.cat([h, z.dense()], -1))
        if head_out is None:
            head_out = self.heads({"h": h, "z": z})
        return head_out["decoder"]


@dataclass(frozen=True)
class WorldModelSettings(RSSMSettings):
    """A concrete `WorldModelConfig` for algorithms that fix some of its fields (PlaNet)."""

    mlp_layers: int = 2
    cnn_depth: int = 32
    symlog_inputs: bool = False
    symlog_targets: bool = False
    reward_head: str = "mse"
    bins: int = 255
    cont_head: bool = False


def world_model_weights(wm: WorldModel) -> Weights:
    """The world model's parameters as numpy arrays under 'wm.*' (what policies load)."""
    return {f"wm.{k}": v.detach().cpu().numpy() for k, v in wm.state_dict().items()}


def load_world_model(wm: WorldModel, weights: Weights) -> WorldModel:
    """Load the 'wm.*' entries of a weight snapshot into `wm` and return it."""
    wm_sd = {k[3:]: torch.as_tensor(np.array(v)) for k, v in weights.items() if k.startswith("wm.")}
    if not wm_sd:
        raise ValueError("weights need 'wm.*' entries (the world model)")
    wm.load_state_dict(wm_sd)
    return wm
