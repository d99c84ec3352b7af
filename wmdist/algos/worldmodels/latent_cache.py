"""V's encodings of replayed windows, kept while V is frozen (stage 2 on).

M trains on whole episodes (hundreds of frames per window), and encoding a window's frames
costs far more than M's own update; the rate limiter replays each stored window many times,
so each is encoded once. The paper does the same offline: every frame is encoded once after V
is trained, and M trains on the stored (mu, logvar) series.

A window is keyed by a digest of its frames' bytes, so a slot that replay overwrote with a new
window misses, and nothing depends on replay's slot ids.
"""
from __future__ import annotations

import hashlib
from collections import OrderedDict
from typing import Callable

import numpy as np
import torch

Encoder = Callable[[torch.Tensor], tuple[torch.Tensor, torch.Tensor]]  # uint8 [N, 64, 64, C] -> mu, logvar [N, Z]


def window_key(frames: np.ndarray) -> bytes:
    """16-byte digest of one window's frames [T, 64, 64, C] (and its shape)."""
    h = hashlib.blake2b(digest_size=16)
    h.update(repr(frames.shape).encode())
    h.update(memoryview(np.ascontiguousarray(frames)).cast("B"))
    return h.digest()


@torch.no_grad()
def encode_windows(obs: np.ndarray,  # uint8 [M, T, 64, 64, C]
                   encoder: Encoder, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """mu, logvar [M, T, Z] of every frame, in one encoder call (a copy: replay arrays may be read-only)."""
    frames = torch.as_tensor(np.array(obs), device=device)
    mu, logvar = encoder(frames.flatten(0, 1))
    return mu.unflatten(0, frames.shape[:2]), logvar.unflatten(0, frames.shape[:2])


class LatentCache:
    """LRU map: window digest -> (mu, logvar) [T, Z] each, on the encoder's device."""

    def __init__(self, max_windows: int) -> None:
        if max_windows < 1:
            raise ValueError(f"max_windows must be >= 1, got {max_windows}")
        self.max_windows = max_windows
        self._store: OrderedDict[bytes, tuple[torch.Tensor, torch.Tensor]] = OrderedDict()
        self.hits = self.misses = 0

    def __len__(self) -> int:
        return len(self._store)

    def clear(self) -> None:
        self._store.clear()

    @torch.no_grad()
    def encode(self, obs: np.ndarray,  # uint8 [B, T, 64, 64, C]
               encoder: Encoder, device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
        """mu, logvar [B, T, Z]: cached windows looked up, the others encoded in one call."""
        keys = [window_key(w) for w in obs]
        missing = [i for i, k in enumerate(keys) if k not in self._store]
        if missing:
            mu, logvar = encode_windows(obs[missing], encoder, device)  # [M, T, Z] each
            for j, i in enumerate(missing):
                self._store[keys[i]] = (mu[j], logvar[j])
        self.hits += len(keys) - len(missing)
        self.misses += len(missing)
        out = [self._store[k] for k in keys]
        for k in keys:
            self._store.move_to_end(k)
        while len(self._store) > self.max_windows:
            self._store.popitem(last=False)
        return torch.stack([o[0] for o in out]), torch.stack([o[1] for o in out])
