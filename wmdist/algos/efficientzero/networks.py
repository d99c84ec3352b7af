"""EfficientZero's network: MuZero's h, g, f (reused as they are) plus an LSTM value-prefix
head in place of the reward head, and the projector / predictor of the consistency loss.

    s^k, x^k = transition(s^{k-1}, a^k)       MuZero's dynamics without its reward head
    P^k, (h, c)^k = LSTM(reduce(x^k), (h, c)^{k-1})   value prefix: rewards summed since the last reset
    proj(s) = BN(W3 ReLU(BN(W2 ReLU(BN(W1 s)))))      projector (authors' code: Linear-BN-ReLU twice, Linear-BN)
    pred(z) = W5 ReLU(BN(W4 z))                        predictor

The authors' batch norm after the LSTM is left out (the search calls the head at batch 1).
"""
from __future__ import annotations

from typing import Any

import torch
from torch import nn

from wmdist.algos.muzero.networks import MuZeroNet
from wmdist.nets.mlp import mlp

LSTMState = tuple[torch.Tensor, torch.Tensor]  # (h [B, H], c [B, H])


class PrefixHead(nn.Module):
    """reduce(features) -> LSTMCell -> ReLU -> MLP -> value-prefix logits [B, 2Sr+1]."""

    def __init__(self, reduce: nn.Module, in_dim: int, lstm_hidden: int, hidden: list[int], atoms: int) -> None:
        super().__init__()
        self.reduce = reduce
        self.lstm = nn.LSTMCell(in_dim, lstm_hidden)
        self.out = mlp(lstm_hidden, hidden, atoms, out_init_zero=True)

    def forward(self, features: torch.Tensor, state: LSTMState) -> tuple[torch.Tensor, LSTMState]:
        h, c = self.lstm(self.reduce(features).flatten(1), state)
        return self.out(torch.relu(h)), (h, c)


def conv_reduce(channels: int, head_channels: int) -> nn.Module:
    """The 1x1 conv + BN + ReLU the authors put before the LSTM on image latents."""
    return nn.Sequential(nn.Conv2d(channels, head_channels, 1), nn.BatchNorm2d(head_channels), nn.ReLU())


class ConsistencyHeads(nn.Module):
    """SimSiam-style projector and predictor on a flattened latent."""

    def __init__(self, latent_numel: int, proj_hidden: int, proj_dim: int, pred_hidden: int) -> None:
        super().__init__()
        self.projector = nn.Sequential(
            nn.Linear(latent_numel, proj_hidden), nn.BatchNorm1d(proj_hidden), nn.ReLU(),
            nn.Linear(proj_hidden, proj_hidden), nn.BatchNorm1d(proj_hidden), nn.ReLU(),
            nn.Linear(proj_hidden, proj_dim), nn.BatchNorm1d(proj_dim))
        self.predictor = nn.Sequential(
            nn.Linear(proj_dim, pred_hidden), nn.BatchNorm1d(pred_hidden), nn.ReLU(), nn.Linear(pred_hidden, proj_dim))

    def project(self, latent: torch.Tensor) -> torch.Tensor:  # [B, *latent] -> [B, P]
        return self.projector(latent.flatten(1))

    def predict(self, projected: torch.Tensor) -> torch.Tensor:  # [B, P] -> [B, P]
        return self.predictor(projected)


class EfficientZeroNet(MuZeroNet):
    """A MuZero network (`base`) with an optional value-prefix head (which replaces its reward
    head) and optional consistency heads."""

    def __init__(self, base: MuZeroNet, prefix: PrefixHead | None, consistency: ConsistencyHeads | None) -> None:
        super().__init__()
        self.base = base
        self.num_actions = base.num_actions
        self.prefix = prefix
        self.consistency = consistency
        self.has_value_prefix = prefix is not None
        if prefix is not None:
            base.reward_head = None  # the prefix head predicts what it did; no unused weights

    def represent(self, obs: torch.Tensor) -> torch.Tensor:
        return self.base.represent(obs)

    def transition(self, latent: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.base.transition(latent, action)

    def dynamics(self, latent: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        if self.prefix is not None:
            raise ValueError("this network predicts value prefixes: call recurrent_inference_prefix")
        return self.base.dynamics(latent, action)

    def predict(self, latent: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.base.predict(latent)

    def initial_state(self, batch: int, device: torch.device | str = "cpu") -> LSTMState:
        """Zero LSTM state (h, c), each [B, H]: the state at a reset."""
        if self.prefix is None:
            raise ValueError("this network has no value-prefix head")
        hidden = self.prefix.lstm.hidden_size
        return torch.zeros(batch, hidden, device=device), torch.zeros(batch, hidden, device=device)

    def recurrent_inference_prefix(self, latent: torch.Tensor, action: torch.Tensor, state: LSTMState,
                                   base: Any = None):
        """(s^{k-1}, a^k, LSTM state) -> (s^k, new state, prefix logits, policy logits, value logits).
        `base`: a stand-in for `self.base`'s transition and predict (the searcher's folded conv path)."""
        base = self.base if base is None else base
        nxt, features = base.transition(latent, action)
        prefix_logits, state = self.prefix(features, state)
        logits, value = base.predict(nxt)
        return nxt, state, prefix_logits, logits, value
