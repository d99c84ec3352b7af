"""Multi-layer perceptron used by every vector encoder and head."""
from __future__ import annotations

from typing import Sequence

from torch import nn

ACTIVATIONS: dict[str, type[nn.Module]] = {"relu": nn.ReLU, "elu": nn.ELU, "silu": nn.SiLU, "tanh": nn.Tanh}


def mlp(
    in_dim: int,
    hidden: Sequence[int],
    out_dim: int | None,
    act: str = "relu",
    norm: bool = False,
    out_init_zero: bool = False,
    dropout: float = 0.0,
) -> nn.Sequential:
    """Linear -> [LayerNorm] -> act for each hidden width, then an optional linear output.

    norm=True gives DreamerV3's LayerNorm + SiLU blocks (bias dropped before the norm).
    out_init_zero starts the output layer at zero (e.g. reward/value heads that should
    predict 0 at initialisation). dropout > 0 follows each hidden activation (train mode only).
    """
    if act not in ACTIVATIONS:
        raise ValueError(f"unknown activation {act!r}; choose one of {sorted(ACTIVATIONS)}")
    layers: list[nn.Module] = []
    d = in_dim
    for h in hidden:
        layers.append(nn.Linear(d, h, bias=not norm))
        if norm:
            layers.append(nn.LayerNorm(h, eps=1e-3))
        layers.append(ACTIVATIONS[act]())
        if dropout > 0:
            layers.append(nn.Dropout(dropout))
        d = h
    if out_dim is not None:
        out = nn.Linear(d, out_dim)
        if out_init_zero:
            nn.init.zeros_(out.weight)
            nn.init.zeros_(out.bias)
        layers.append(out)
    return nn.Sequential(*layers)
