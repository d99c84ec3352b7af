"""Residual convolutional towers (MuZero Appendix F, after AlphaZero's network)."""
from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F


class ResidualBlock(nn.Module):
    """conv3x3 -> BN -> ReLU -> conv3x3 -> BN, plus the skip, then ReLU; keeps [B, C, H, W]."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(channels, channels, 3, padding=1, bias=False)
        self.bn1 = nn.BatchNorm2d(channels)
        self.conv2 = nn.Conv2d(channels, channels, 3, padding=1, bias=False)
        self.bn2 = nn.BatchNorm2d(channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = F.relu(self.bn1(self.conv1(x)))
        y = self.bn2(self.conv2(y))
        return F.relu(x + y)


def res_tower(channels: int, blocks: int) -> nn.Sequential:
    """`blocks` residual blocks of `channels` channels."""
    return nn.Sequential(*[ResidualBlock(channels) for _ in range(blocks)])


class AtariDownsample(nn.Module):
    """MuZero's Atari downsampling: 96x96 -> 6x6 (any H, W: each stage halves, rounding up).

    conv stride 2 (C/2 channels) -> 2 res blocks -> conv stride 2 (C) -> 3 res blocks ->
    avg-pool stride 2 -> 3 res blocks -> avg-pool stride 2.
    """

    def __init__(self, in_channels: int, channels: int, blocks: tuple[int, int, int] = (2, 3, 3)) -> None:
        super().__init__()
        half = channels // 2
        self.conv1 = nn.Conv2d(in_channels, half, 3, stride=2, padding=1, bias=False)
        self.bn1 = nn.BatchNorm2d(half)
        self.tower1 = res_tower(half, blocks[0])
        self.conv2 = nn.Conv2d(half, channels, 3, stride=2, padding=1, bias=False)
        self.bn2 = nn.BatchNorm2d(channels)
        self.tower2 = res_tower(channels, blocks[1])
        self.tower3 = res_tower(channels, blocks[2])

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # [B, Cin, H, W] -> [B, C, H/16, W/16]
        x = self.tower1(F.relu(self.bn1(self.conv1(x))))
        x = self.tower2(F.relu(self.bn2(self.conv2(x))))
        x = F.avg_pool2d(x, 3, stride=2, padding=1)
        x = self.tower3(x)
        return F.avg_pool2d(x, 3, stride=2, padding=1)
