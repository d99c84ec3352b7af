"""Build the MuZero network for an EnvSpec, and move weights to and from numpy."""
from __future__ import annotations

import numpy as np
import torch

from wmdist.algos.base import Weights
from wmdist.algos.muzero.config import MuZeroConfig
from wmdist.algos.muzero.networks import MLPNet, MuZeroNet
from wmdist.algos.muzero.networks_conv import ConvNet
from wmdist.algos.muzero.rules_model import rules_for
from wmdist.envs.spec import EnvSpec


def check_spec(spec: EnvSpec, cfg: MuZeroConfig) -> None:
    """Raise ValueError (one line) if MuZero can't run on this env."""
    if not spec.discrete:
        raise ValueError(f"muzero needs discrete actions; {spec.id} has continuous actions {spec.action_shape}")
    if spec.players not in (1, 2):
        raise ValueError(f"muzero supports 1 or 2 players, {spec.id} has {spec.players}")
    if cfg.augment_symmetries and not spec.symmetries:
        raise ValueError(f"algo.augment_symmetries needs a board game with declared symmetries; {spec.id} has none")
    if cfg.tree_model == "rules":
        rules_for(spec)
    kind = network_kind(spec, cfg)
    if kind == "conv" and len(spec.obs_shape) != 3:
        raise ValueError(f"algo.network=conv needs (H, W, C) image observations, {spec.id} has {spec.obs_shape}")


def network_kind(spec: EnvSpec, cfg: MuZeroConfig) -> str:
    if cfg.network != "auto":
        return cfg.network
    return "conv" if spec.obs_kind == "image" else "mlp"


def build_net(spec: EnvSpec, cfg: MuZeroConfig) -> MuZeroNet:
    check_spec(spec, cfg)
    hidden = [int(w) for w in cfg.hidden]
    va, ra = 2 * cfg.value_support + 1, 2 * cfg.reward_support + 1
    if network_kind(spec, cfg) == "conv":
        h, w, c = spec.obs_shape
        return ConvNet((h, w, c), spec.num_actions, cfg.conv_channels, cfg.conv_blocks,
                       cfg.conv_head_channels, hidden, va, ra,
                       downsample_blocks=tuple(int(b) for b in cfg.conv_downsample_blocks), stem=cfg.conv_stem)
    obs_dim = int(np.prod(spec.obs_shape))
    return MLPNet(obs_dim, spec.num_actions, cfg.latent_dim, hidden, va, ra)


def to_numpy_weights(net: torch.nn.Module) -> Weights:
    """Parameters and buffers (BatchNorm statistics) as contiguous numpy arrays."""
    return {k: v.detach().cpu().numpy().copy() for k, v in net.state_dict().items()}


def load_numpy_weights(net: torch.nn.Module, weights: Weights) -> None:
    own = net.state_dict()
    missing = set(own) - set(weights)
    if missing:
        raise ValueError(f"weight snapshot lacks {len(missing)} tensors, e.g. '{sorted(missing)[0]}'")
    net.load_state_dict({k: torch.tensor(np.asarray(weights[k])) for k in own})
