"""V and M built from the config, and their weights as flat numpy dicts (`vae.*`, `rnn.*`)."""
from __future__ import annotations

import numpy as np
import torch

from wmdist.algos.worldmodels.config import WorldModelsConfig
from wmdist.algos.worldmodels.mdn import MDNRNN
from wmdist.algos.worldmodels.vae import ConvVAE
from wmdist.envs.spec import EnvSpec


def build_vae(cfg: WorldModelsConfig, spec: EnvSpec) -> ConvVAE:
    return ConvVAE(spec.obs_shape[-1], cfg.z_dim, cfg.vae_depth)


def build_rnn(cfg: WorldModelsConfig, spec: EnvSpec) -> MDNRNN:
    return MDNRNN(cfg.z_dim, spec.action_dim, cfg.rnn_hidden, cfg.mixtures)


def to_numpy(module: torch.nn.Module, prefix: str) -> dict[str, np.ndarray]:
    return {f"{prefix}.{k}": v.detach().cpu().numpy().copy() for k, v in module.state_dict().items()}


def load_numpy(module: torch.nn.Module, weights: dict[str, np.ndarray], prefix: str) -> None:
    n = len(prefix) + 1
    module.load_state_dict({k[n:]: torch.as_tensor(np.asarray(v)) for k, v in weights.items()
                            if k.startswith(prefix + ".")})
