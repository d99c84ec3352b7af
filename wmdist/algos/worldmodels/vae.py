"""V: the convolutional VAE that compresses each 64x64 frame to z (World Models, sec. 2.1).

Encoder and decoder are the project's 64x64 conv stacks (`wmdist.nets.conv`, 32-64-128-256
channels, ReLU, no norm as in the paper); the paper's encoder uses unpadded convolutions (a
2x2x256 map) where these pad to 4x4x256, and the decoder ends in a sigmoid (pixels in [0, 1]).

Loss per frame (the authors' code, docs/reference.md#world-models):
    recon = sum_pixels (x - x_hat)^2                     (x in [0, 1])
    kl    = max(KL(N(mu, sigma^2) || N(0, I)), kl_tolerance * z_dim)   (free bits)
"""
from __future__ import annotations

import torch
from torch import nn

from wmdist.nets.conv import ConvDecoder, ConvEncoder


class ConvVAE(nn.Module):
    def __init__(self, channels: int, z_dim: int = 32, depth: int = 32) -> None:
        super().__init__()
        self.z_dim = z_dim
        self.encoder = ConvEncoder(channels, depth, act="relu", norm=False)
        self.stats = nn.Linear(self.encoder.out_dim, 2 * z_dim)  # -> mu, logvar
        self.decoder = ConvDecoder(z_dim, channels, depth, act="relu", norm=False)

    def encode(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """uint8 [N, 64, 64, C] -> mu, logvar [N, Z]."""
        mu, logvar = self.stats(self.encoder(obs)).chunk(2, -1)
        return mu, logvar

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """[N, Z] -> pixels in [0, 1], channels-last [N, 64, 64, C]."""
        return torch.sigmoid(self.decoder(z))

    @staticmethod
    def sample(mu: torch.Tensor, logvar: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
        """z = mu + sigma * eps (the reparameterisation trick)."""
        eps = torch.randn(mu.shape, generator=generator, device=mu.device, dtype=mu.dtype)
        return mu + torch.exp(0.5 * logvar) * eps


def vae_terms(mu: torch.Tensor, logvar: torch.Tensor, recon: torch.Tensor, obs: torch.Tensor
              ) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-frame (reconstruction, KL) [N] each.

    mu, logvar [N, Z]; recon [N, H, W, C] in [0, 1]; obs uint8 [N, H, W, C].
    KL(N(mu, sigma^2) || N(0, 1)) = 0.5 * sum(mu^2 + sigma^2 - 1 - log sigma^2)   (Kingma & Welling, app. B)
    """
    target = obs.float() / 255.0
    rec = (recon - target).pow(2).flatten(1).sum(-1)  # [N]
    kl = 0.5 * (mu.pow(2) + logvar.exp() - 1.0 - logvar).sum(-1)  # [N]
    return rec, kl


def vae_loss(rec: torch.Tensor, kl: torch.Tensor, kl_tolerance: float, z_dim: int) -> torch.Tensor:
    """Batch mean of recon + max(KL, tolerance * Z) (free bits: the KL is not pushed below them)."""
    return (rec + torch.clamp(kl, min=kl_tolerance * z_dim)).mean()
