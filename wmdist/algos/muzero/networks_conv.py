"""Convolutional MuZero networks for image observations (paper Appendix F, Atari).

Representation: the Atari downsampling stack (96x96 -> 6x6) then a residual tower; for
small grids (MinAtar's 10x10, where four halvings would leave 1x1) a full-resolution
3x3 conv stem instead (`stem="grid"`).
Dynamics: the hidden state concatenated with one-hot action planes ([B, A, h, w]), a conv
back to C channels, a residual tower. Heads: 1x1 convs, then small MLPs.
Departure: the paper feeds 32 past frames plus 32 past-action planes; here the observation
is whatever the env stacks (e.g. 4 grey frames), without past-action planes.
"""
from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from wmdist.algos.muzero.networks import MuZeroNet, scale_latent
from wmdist.nets.mlp import mlp
from wmdist.nets.resnet import AtariDownsample, res_tower


def _down(n: int) -> int:
    """Side after one stride-2 stage with padding 1 (kernel 3)."""
    return (n + 1) // 2


class _Head(nn.Module):
    """1x1 conv to a few channels -> flatten -> MLP -> out."""

    def __init__(self, channels: int, head_channels: int, side: tuple[int, int], hidden: list[int], out: int) -> None:
        super().__init__()
        self.conv = nn.Conv2d(channels, head_channels, 1)
        self.bn = nn.BatchNorm2d(head_channels)
        self.fc = mlp(head_channels * side[0] * side[1], hidden, out, out_init_zero=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # [B, C, h, w] -> [B, out]
        return self.fc(F.relu(self.bn(self.conv(x))).flatten(1))


class GridStem(nn.Module):
    """[B, Cin, H, W] -> [B, C, H, W]: one 3x3 conv, BN, ReLU; no downsampling."""

    def __init__(self, in_channels: int, channels: int) -> None:
        super().__init__()
        self.conv = nn.Conv2d(in_channels, channels, 3, padding=1, bias=False)
        self.bn = nn.BatchNorm2d(channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.bn(self.conv(x)))


class ConvNet(MuZeroNet):
    def __init__(
        self,
        obs_shape: tuple[int, int, int],  # (H, W, C) channels-last uint8
        num_actions: int,
        channels: int,
        blocks: int,
        head_channels: int,
        hidden: list[int],
        value_atoms: int,
        reward_atoms: int,
        downsample_blocks: tuple[int, int, int] = (2, 3, 3),
        stem: str = "atari",
    ) -> None:
        super().__init__()
        h, w, c = obs_shape
        self.num_actions = num_actions
        side = (h, w)
        if stem == "grid":
            self.down: nn.Module = GridStem(c, channels)
        elif stem == "atari":
            self.down = AtariDownsample(c, channels, downsample_blocks)
            for _ in range(4):  # two strided convs and two strided pools
                side = (_down(side[0]), _down(side[1]))
        else:
            raise ValueError(f"conv stem must be 'atari' or 'grid', got {stem!r}")
        self.repr_tower = res_tower(channels, blocks)
        self.dyn_conv = nn.Conv2d(channels + num_actions, channels, 3, padding=1, bias=False)
        self.dyn_bn = nn.BatchNorm2d(channels)
        self.dyn_tower = res_tower(channels, blocks)
        self.reward_head = _Head(channels, head_channels, side, hidden, reward_atoms)
        self.pred_tower = res_tower(channels, blocks)
        self.policy_head = _Head(channels, head_channels, side, hidden, num_actions)
        self.value_head = _Head(channels, head_channels, side, hidden, value_atoms)

    def represent(self, obs: torch.Tensor) -> torch.Tensor:
        x = obs.permute(0, 3, 1, 2).float() / 255.0  # [B, C, H, W] in [0, 1]
        return scale_latent(self.repr_tower(self.down(x)))  # [B, C, h, w]

    def transition(self, latent: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        b, _, hh, ww = latent.shape
        planes = F.one_hot(action.long(), self.num_actions).to(latent.dtype)  # [B, A]
        planes = planes[:, :, None, None].expand(b, self.num_actions, hh, ww)  # [B, A, h, w]
        x = F.relu(self.dyn_bn(self.dyn_conv(torch.cat([latent, planes], dim=1))))
        x = self.dyn_tower(x)
        return scale_latent(x), x  # the reward head reads the tower's output before scaling

    def predict(self, latent: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        x = self.pred_tower(latent)
        return self.policy_head(x), self.value_head(x)
