"""The JEPA world model: encoder + projector (frame -> embedding) and an action-conditioned
predictor (a short history of embeddings and actions -> the next embedding). No decoder.

Observations are [..., 64, 64, 6] uint8: the current frame and the goal image, 3 channels
each (`wmdist/envs/nav.py`); both halves go through the same encoder.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from wmdist.algos.base import Weights
from wmdist.algos.jepa.config import JepaConfig
from wmdist.nets.conv import ConvEncoder
from wmdist.nets.mlp import ACTIVATIONS, mlp

FRAME_CHANNELS = 3  # one RGB frame; an observation is the current frame then the goal image
UPDATES_KEY = "jepa.updates"  # extra entry of the published weights: learner updates behind them
GRAPH_KEY = "jepa.graph"  # extra entry with algo.graph_pairs: [2P, D] embeddings, rows 2i -> 2i+1 one real step


class Projector(nn.Module):
    """Linear-BN-act-Linear-BN (LeWM: a BatchNorm projector). The batch norms put every embedding
    dimension at unit scale from the start, however little the frames differ (a few pixels of a
    point mass), so SIGReg shapes the distribution instead of first fighting a near-constant encoder;
    they use running statistics in eval mode (acting). Without the last one (`out_norm` False) nothing
    but SIGReg holds the embedding's scale up: the collapse ablation's clean form."""

    def __init__(self, in_dim: int, hidden: int, out_dim: int, act: str, out_norm: bool = True) -> None:
        super().__init__()
        layers: list[nn.Module] = [nn.Linear(in_dim, hidden, bias=False), nn.BatchNorm1d(hidden), ACTIVATIONS[act](),
                                   nn.Linear(hidden, out_dim, bias=not out_norm)]
        if out_norm:
            layers.append(nn.BatchNorm1d(out_dim))
        self.net = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # [..., F] -> [..., D]
        return self.net(x.reshape(-1, x.shape[-1])).reshape(*x.shape[:-1], -1)


class JepaModel(nn.Module):
    def __init__(self, cfg: JepaConfig, action_dim: int) -> None:
        super().__init__()
        self.cfg, self.action_dim = cfg, action_dim
        self.conv = ConvEncoder(FRAME_CHANNELS, cfg.cnn_depth, cfg.act, norm=True)
        self.projector = Projector(self.conv.out_dim, cfg.proj_hidden, cfg.embed_dim, cfg.act, cfg.proj_out_norm)
        self.predictor = mlp(cfg.history * (cfg.embed_dim + action_dim), [cfg.pred_hidden] * cfg.pred_layers,
                             cfg.embed_dim, cfg.act, norm=True, dropout=cfg.pred_dropout)
        # SIGReg's input when `sigreg_head` > 0: trained only through SIGReg, never used to plan
        self.sigreg_head = Projector(cfg.embed_dim, cfg.sigreg_head, cfg.sigreg_head_dim, cfg.act) \
            if cfg.sigreg_head else None

    def regularised(self, z: torch.Tensor) -> torch.Tensor:
        """What SIGReg tests: [N, D] embeddings -> [N, D'] (the head's output, or z itself)."""
        return z if self.sigreg_head is None else self.sigreg_head(z)

    def encode(self, frames: torch.Tensor) -> torch.Tensor:
        """uint8 [..., 64, 64, 3] -> embeddings [..., D]."""
        return self.projector(self.conv(frames))

    def encode_obs(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """uint8 [..., 64, 64, 6] -> (current frame's embedding [..., D], goal image's [..., D])."""
        both = torch.stack([obs[..., :FRAME_CHANNELS], obs[..., FRAME_CHANNELS:]], 0)  # [2, ..., 64, 64, 3]
        z = self.encode(both)
        return z[0], z[1]

    def predict(self, z_hist: torch.Tensor,  # [N, h, D] the last h embeddings, oldest first
                a_hist: torch.Tensor,  # [N, h, A] the actions taken at them
                ) -> torch.Tensor:
        """The next embedding [N, D]: z_t plus the predictor's change (a residual keeps the
        untrained predictor near the identity, so early plans stay where they are)."""
        x = torch.cat([z_hist, a_hist], -1).flatten(1)  # [N, h * (D + A)]
        return z_hist[:, -1] + self.predictor(x)


@torch.no_grad()
def recalibrate_batchnorm(model: JepaModel, frames: torch.Tensor, chunk: int = 512) -> None:
    """Set every BatchNorm's running statistics to those of `frames` (uint8 [N, 64, 64, 3]) under
    the current weights: the average over chunks of `chunk` frames (exact for one chunk).

    Training normalises with batch statistics, acting with the running ones; torch's running
    average (momentum 0.1) mixes ~10 batches of older weights, and the embeddings planning
    compares move with it (issue 23: 35% vs 85% success for the same weights).
    """
    # the encoder's and projector's only: the SIGReg head is not on the planning path
    bns = [m for part in (model.conv, model.projector) for m in part.modules()
           if isinstance(m, nn.modules.batchnorm._BatchNorm)]
    if not bns or frames.shape[0] == 0:
        return
    was_training, momenta = model.training, [m.momentum for m in bns]
    for m in bns:
        m.reset_running_stats()
        m.momentum = None  # a cumulative average over the chunks below
    model.train()
    try:
        for i in range(0, frames.shape[0], chunk):
            model.encode(frames[i:i + chunk])
    finally:
        for m, mom in zip(bns, momenta):
            m.momentum = mom
        model.train(was_training)


def model_weights(model: JepaModel, updates: int) -> Weights:
    """The published snapshot: the state dict as numpy, plus the update count behind it."""
    out = {k: v.detach().cpu().numpy().copy() for k, v in model.state_dict().items()}
    out[UPDATES_KEY] = np.asarray(updates, np.int64)
    return out


def load_model(model: JepaModel, weights: Weights) -> int:
    """Load a snapshot into `model`; returns the learner updates behind it."""
    state = {k: torch.as_tensor(np.array(v)) for k, v in weights.items() if k not in (UPDATES_KEY, GRAPH_KEY)}
    model.load_state_dict(state)
    return int(weights.get(UPDATES_KEY, 0))
