"""Actions between env space and the model's input: one-hot indices, or bounds mapped to [-1, 1]."""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from wmdist.envs.spec import EnvSpec


def action_to_model(action: torch.Tensor, spec: EnvSpec) -> torch.Tensor:
    """Stored actions [..] or [.., D] -> model input [.., A]: one-hot, or rescaled to [-1, 1]."""
    if spec.discrete:
        return F.one_hot(action.long().clamp(0, spec.num_actions - 1), spec.num_actions).float()
    lo, hi = bounds(spec)
    low = torch.as_tensor(lo, device=action.device)
    high = torch.as_tensor(hi, device=action.device)
    return (2 * (action.float() - low) / (high - low) - 1).clamp(-1, 1)


def action_to_env(action: torch.Tensor, spec: EnvSpec) -> np.ndarray:
    """Model actions (indices [E], or [E, D] in [-1, 1]) -> env actions of the spec's dtype."""
    if spec.discrete:
        return action.long().cpu().numpy().astype(np.int64)
    low, high = bounds(spec)
    a = np.clip(action.detach().float().cpu().numpy(), -1, 1)
    return (low + (a + 1) * 0.5 * (high - low)).astype(np.float32).reshape(-1, *spec.action_shape)


def bounds(spec: EnvSpec) -> tuple[np.ndarray, np.ndarray]:
    """Action bounds [D] (a spec without bounds means [-1, 1])."""
    d = spec.action_dim
    low = np.asarray(spec.action_low or (-1.0,) * d, np.float32).reshape(-1)
    high = np.asarray(spec.action_high or (1.0,) * d, np.float32).reshape(-1)
    return low, high
