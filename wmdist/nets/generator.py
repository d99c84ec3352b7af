"""Seeded torch generators for a role's device.

A model built on the `meta` device (the model-size check before a run starts allocates no
memory) has no generator of its own: torch refuses `Generator("meta")`. It gets a CPU one,
which nothing ever draws from there.
"""
from __future__ import annotations

import torch


def seeded_generator(device: torch.device | str, seed: int) -> torch.Generator:
    device = torch.device(device)
    if device.type == "meta":
        device = torch.device("cpu")
    return torch.Generator(device).manual_seed(seed)
