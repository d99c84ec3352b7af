"""Polyak averaging: move one module's parameters a step towards another's."""
from __future__ import annotations

import torch


@torch.no_grad()
def polyak_(average: torch.nn.Module, source: torch.nn.Module, mix: float, copy_buffers: bool = True) -> None:
    """average <- (1 - mix) * average + mix * source, per parameter, in place; buffers (BatchNorm
    statistics) are copied, since averaging running statistics of different weights means little."""
    for a, s in zip(average.parameters(), source.parameters()):
        a.lerp_(s.detach(), mix)
    if copy_buffers:
        for a, s in zip(average.buffers(), source.buffers()):
            a.copy_(s)
