"""MuZero's three functions (paper Eq. 1 / Figure 1): representation h, dynamics g, prediction f.

    s^0 = h(o_t)                 representation
    r^k, s^k = g(s^{k-1}, a^k)   dynamics (reward as logits over a support)
    p^k, v^k = f(s^k)            prediction (policy logits, value logits over a support)

Hidden states are min-max scaled to [0, 1] per sample (paper Appendix G) after h and g.
`MuZeroNet` is the interface; `MLPNet` serves vector observations, `ConvNet`
(networks_conv.py) images.
"""
from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from wmdist.nets.mlp import mlp


def scale_latent(s: torch.Tensor) -> torch.Tensor:
    """Min-max scale each sample's hidden state to [0, 1] over all its non-batch dims."""
    flat = s.flatten(1)
    lo = flat.min(dim=1, keepdim=True).values
    hi = flat.max(dim=1, keepdim=True).values
    return ((flat - lo) / (hi - lo).clamp_min(1e-5)).view_as(s)


def scale_gradient(x: torch.Tensor, scale: float) -> torch.Tensor:
    """Identity forward; multiplies the gradient flowing back through `x` by `scale`."""
    return x * scale + x.detach() * (1.0 - scale)


class MuZeroNet(nn.Module):
    """Common interface of the MuZero networks (latents are tensors with batch first)."""

    num_actions: int
    has_value_prefix: bool = False  # EfficientZero's LSTM value-prefix head (searcher: recurrent_fn takes `reset`)

    def represent(self, obs: torch.Tensor) -> torch.Tensor:  # [B, *obs] -> [B, *latent]
        raise NotImplementedError

    def transition(self, latent: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """([B, *latent], [B] int64) -> (next latent [B, *latent], the features the reward head reads)."""
        raise NotImplementedError

    def dynamics(self, latent: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """([B, *latent], [B] int64) -> (next latent [B, *latent], reward logits [B, 2Sr+1])."""
        nxt, features = self.transition(latent, action)
        return nxt, self.reward_head(features)

    def predict(self, latent: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """[B, *latent] -> (policy logits [B, A], value logits [B, 2Sv+1])."""
        raise NotImplementedError

    def initial_inference(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """obs -> (latent, policy logits, value logits)."""
        s = self.represent(obs)
        logits, value = self.predict(s)
        return s, logits, value

    def recurrent_inference(
        self, latent: torch.Tensor, action: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """(latent, action) -> (next latent, reward logits, policy logits, value logits)."""
        s, reward = self.dynamics(latent, action)
        logits, value = self.predict(s)
        return s, reward, logits, value


class MLPNet(MuZeroNet):
    """MLP networks for vector observations; the action enters the dynamics one-hot."""

    def __init__(
        self,
        obs_dim: int,
        num_actions: int,
        latent_dim: int,
        hidden: list[int],
        value_atoms: int,
        reward_atoms: int,
    ) -> None:
        super().__init__()
        self.num_actions = num_actions
        self.repr_net = mlp(obs_dim, hidden, latent_dim)
        self.dyn_net = mlp(latent_dim + num_actions, hidden, latent_dim)
        self.reward_head = mlp(latent_dim, hidden, reward_atoms, out_init_zero=True)
        self.policy_head = mlp(latent_dim, hidden, num_actions, out_init_zero=True)
        self.value_head = mlp(latent_dim, hidden, value_atoms, out_init_zero=True)

    def represent(self, obs: torch.Tensor) -> torch.Tensor:
        return scale_latent(self.repr_net(obs.flatten(1).float()))  # [B, D]

    def transition(self, latent: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        a = F.one_hot(action.long(), self.num_actions).to(latent.dtype)  # [B, A]
        nxt = scale_latent(self.dyn_net(torch.cat([latent, a], dim=-1)))  # [B, D]
        # The reward of the transition is read from the new state (as in muzero-general's MLP).
        return nxt, nxt

    def predict(self, latent: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.policy_head(latent), self.value_head(latent)
