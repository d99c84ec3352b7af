"""Optimiser, learning-rate schedule and a guarded gradient step shared by all learners."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

import torch

from wmdist.algos.base import NonFiniteLoss
from wmdist.config.fields import param


@dataclass
class OptimConfig:
    """One optimiser's settings (an algorithm embeds one per optimiser it owns)."""

    kind: str = param("adam", "optimiser", choices=("adam", "adamw", "sgd"))
    lr: float = param(1e-3, "peak learning rate", gt=0)
    eps: float = param(1e-8, "Adam epsilon", gt=0)
    momentum: float = param(0.9, "SGD momentum", ge=0, lt=1)
    weight_decay: float = param(0.0, "L2 weight decay (decoupled for adamw)", ge=0)
    clip_norm: float = param(0.0, "clip the global gradient norm to this (0 = off)", ge=0)
    schedule: str = param("constant", "learning-rate schedule", choices=("constant", "step", "cosine", "linear"))
    warmup: int = param(0, "linear warm-up updates", ge=0)
    decay_steps: int = param(100_000, "updates over which the schedule decays", ge=1)
    decay_rate: float = param(0.1, "step/linear: the factor reached after decay_steps", gt=0, le=1)


def make_optimizer(params: Iterable[torch.nn.Parameter], cfg: OptimConfig) -> torch.optim.Optimizer:
    params = [p for p in params if p.requires_grad]
    if cfg.kind == "adam":
        return torch.optim.Adam(params, lr=cfg.lr, eps=cfg.eps, weight_decay=cfg.weight_decay)
    if cfg.kind == "adamw":
        return torch.optim.AdamW(params, lr=cfg.lr, eps=cfg.eps, weight_decay=cfg.weight_decay)
    return torch.optim.SGD(params, lr=cfg.lr, momentum=cfg.momentum, weight_decay=cfg.weight_decay)


def lr_at(cfg: OptimConfig, step: int) -> float:
    """Learning rate after `step` updates."""
    if cfg.warmup and step < cfg.warmup:
        return cfg.lr * (step + 1) / cfg.warmup
    t = min(max(step - cfg.warmup, 0) / cfg.decay_steps, 1.0)
    if cfg.schedule == "step":
        # MuZero: lr * rate^(step / decay_steps), applied smoothly (paper: x0.1 over 350k steps)
        return cfg.lr * cfg.decay_rate ** (max(step - cfg.warmup, 0) / cfg.decay_steps)
    if cfg.schedule == "cosine":
        return cfg.lr * (cfg.decay_rate + (1 - cfg.decay_rate) * 0.5 * (1 + math.cos(math.pi * t)))
    if cfg.schedule == "linear":
        return cfg.lr * (1 - (1 - cfg.decay_rate) * t)
    return cfg.lr


class GuardedStep:
    """Backward + clip + step that refuses a non-finite loss or gradient (nothing changes then)."""

    def __init__(self, params: Iterable[torch.nn.Parameter], cfg: OptimConfig) -> None:
        self.params = [p for p in params if p.requires_grad]
        self.cfg = cfg
        self.optimizer = make_optimizer(self.params, cfg)
        self.steps = 0

    def __call__(self, loss: torch.Tensor) -> float:
        """Apply one update from `loss`; returns the pre-clip gradient norm."""
        return joint_step([(self, loss)])[0]

    def step(self) -> float:
        """Clip and apply the gradients already in the parameters; returns the pre-clip norm."""
        max_norm = self.cfg.clip_norm if self.cfg.clip_norm > 0 else float("inf")
        norm = torch.nn.utils.clip_grad_norm_(self.params, max_norm)
        if not torch.isfinite(norm):
            self.optimizer.zero_grad(set_to_none=True)
            raise NonFiniteLoss(f"gradient norm is {norm.item()}")
        lr = lr_at(self.cfg, self.steps)
        for group in self.optimizer.param_groups:
            group["lr"] = lr
        self.optimizer.step()
        self.steps += 1
        return float(norm)

    def state_dict(self) -> dict:
        return {"optimizer": self.optimizer.state_dict(), "steps": self.steps}

    def load_state_dict(self, state: dict) -> None:
        self.optimizer.load_state_dict(state["optimizer"])
        self.steps = int(state["steps"])


def joint_step(pairs: list[tuple[GuardedStep, torch.Tensor]]) -> list[float]:
    """One backward pass over every loss, then each optimiser's guarded step, in order.

    For losses whose parameter sets take gradients from their own loss only (an actor and a
    critic): the same gradients as separate backward passes, but the losses may share one
    autograd graph (a compiled phase that returns both, whose saved tensors one backward frees).
    Returns the pre-clip gradient norms; a non-finite loss changes nothing.
    """
    for _, loss in pairs:
        if not torch.isfinite(loss.detach()).all():
            raise NonFiniteLoss(f"loss is {loss.detach().float().item()}")
    for opt, _ in pairs:
        opt.optimizer.zero_grad(set_to_none=True)
    torch.autograd.backward([loss for _, loss in pairs])
    return [opt.step() for opt, _ in pairs]
