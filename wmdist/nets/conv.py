"""64x64 image encoder / decoder (Dreamer family): four stride-2 convolutions each way.

Channels double per layer from `depth` (V3 XS/S: 24/32); 64 -> 32 -> 16 -> 8 -> 4.
Images come in channels-last uint8 [N, 64, 64, C] and are mapped to [-0.5, 0.5].
"""
from __future__ import annotations

import torch
from torch import nn

from wmdist.nets.mlp import ACTIVATIONS


class ChannelNorm(nn.Module):
    """LayerNorm over channels at each pixel of [N, C, H, W] (as DreamerV3's conv norm)."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.norm = nn.LayerNorm(channels, eps=1e-3)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.norm(x.permute(0, 2, 3, 1)).permute(0, 3, 1, 2)


def _block(conv: nn.Module, ch: int, act: str, norm: bool) -> list[nn.Module]:
    return [conv, ChannelNorm(ch), ACTIVATIONS[act]()] if norm else [conv, ACTIVATIONS[act]()]


def image_to_input(obs: torch.Tensor) -> torch.Tensor:
    """uint8 [..., H, W, C] -> float [..., C, H, W] in [-0.5, 0.5]."""
    x = obs.float() / 255.0 - 0.5
    return x.movedim(-1, -3)


class ConvEncoder(nn.Module):
    """[N, 64, 64, C] uint8 -> [N, 16 * 8 * depth] features."""

    def __init__(self, in_channels: int, depth: int = 32, act: str = "silu", norm: bool = True) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        c_in = in_channels
        for i in range(4):
            c_out = depth * 2**i
            layers += _block(nn.Conv2d(c_in, c_out, 4, 2, 1, bias=not norm), c_out, act, norm)
            c_in = c_out
        self.net = nn.Sequential(*layers, nn.Flatten())
        self.out_dim = 16 * c_in

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        if obs.shape[-3:-1] != (64, 64):
            raise ValueError(f"ConvEncoder expects 64x64 images, got {tuple(obs.shape[-3:])}")
        lead = obs.shape[:-3]
        x = image_to_input(obs.reshape(-1, *obs.shape[-3:]))
        return self.net(x).reshape(*lead, self.out_dim)


class ConvDecoder(nn.Module):
    """[N, in_dim] features -> [N, 64, 64, C] predicted image in [-0.5, 0.5] space (channels-last)."""

    def __init__(self, in_dim: int, out_channels: int, depth: int = 32, act: str = "silu", norm: bool = True) -> None:
        super().__init__()
        self.depth8 = 8 * depth
        self.fc = nn.Linear(in_dim, 16 * self.depth8)
        layers: list[nn.Module] = []
        c_in = self.depth8
        for i in range(3):
            c_out = depth * 2 ** (2 - i)
            layers += _block(nn.ConvTranspose2d(c_in, c_out, 4, 2, 1, bias=not norm), c_out, act, norm)
            c_in = c_out
        layers.append(nn.ConvTranspose2d(c_in, out_channels, 4, 2, 1))
        self.net = nn.Sequential(*layers)

    def forward(self, feat: torch.Tensor) -> torch.Tensor:
        lead = feat.shape[:-1]
        x = self.fc(feat.reshape(-1, feat.shape[-1])).reshape(-1, self.depth8, 4, 4)
        img = self.net(x)  # [N, C, 64, 64]
        return img.movedim(-3, -1).reshape(*lead, 64, 64, img.shape[1])
