"""Build EfficientZero's network for an EnvSpec from MuZero's networks."""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from wmdist.algos.efficientzero.config import EfficientZeroConfig
from wmdist.algos.efficientzero.networks import ConsistencyHeads, EfficientZeroNet, PrefixHead, conv_reduce
from wmdist.algos.muzero.build import build_net as build_base
from wmdist.algos.muzero.networks import MuZeroNet
from wmdist.envs.spec import EnvSpec


@torch.no_grad()
def _shapes(base: MuZeroNet, spec: EnvSpec) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """(latent shape, reward-feature shape) without the batch dim, from one dummy step."""
    was = base.training
    base.eval()
    obs = torch.zeros((1, *spec.obs_shape), dtype=torch.float32 if spec.obs_dtype.startswith("float") else torch.uint8)
    latent = base.represent(obs)
    _, features = base.transition(latent, torch.zeros(1, dtype=torch.int64))
    base.train(was)
    return tuple(latent.shape[1:]), tuple(features.shape[1:])


def build_net(spec: EnvSpec, cfg: EfficientZeroConfig) -> EfficientZeroNet:
    base = build_base(spec, cfg)  # MuZero's own builder: every network option means the same here
    latent_shape, feature_shape = _shapes(base, spec)
    prefix = None
    if cfg.value_prefix:
        if len(feature_shape) == 3:  # image latents [C, h, w]
            reduce, in_dim = conv_reduce(feature_shape[0], cfg.conv_head_channels), \
                cfg.conv_head_channels * feature_shape[1] * feature_shape[2]
        else:
            reduce, in_dim = nn.Identity(), int(np.prod(feature_shape))
        prefix = PrefixHead(reduce, in_dim, cfg.lstm_hidden, [int(w) for w in cfg.hidden], 2 * cfg.reward_support + 1)
    heads = None
    if cfg.consistency_weight > 0:
        heads = ConsistencyHeads(int(np.prod(latent_shape)), cfg.proj_hidden, cfg.proj_dim, cfg.pred_hidden)
    return EfficientZeroNet(base, prefix, heads)
