"""C: the linear controller on [z_t, h_t] (World Models, sec. 2.3): a_t = W [z_t h_t] + b.

Its parameters are one flat vector (what CMA-ES searches), laid out as W [A, F] row-major
then b [A], with F = Z + H, or F = Z for the paper's controller on z alone (`controller_h:
false`); the vector's length says which, so every caller passes both z and h. Continuous actions squash each output with tanh and rescale it to the action's
bounds (the paper: steering in [-1, 1], gas and brake mapped from tanh to [0, 1]); discrete
actions take the largest output (a departure: the paper's Doom controller thresholds one output).
"""
from __future__ import annotations

import torch

from wmdist.envs.spec import EnvSpec


def num_params(spec: EnvSpec, z_dim: int, hidden: int, reads_h: bool = True) -> int:
    """|W| + |b|: (Z + H) * A + A (CarRacing, Z 32, H 256, A 3: 867, the paper's count); Z * A + A
    without h (99)."""
    a = spec.action_dim
    return (z_dim + (hidden if reads_h else 0)) * a + a


def act_batched(params: torch.Tensor, z: torch.Tensor, h: torch.Tensor, spec: EnvSpec) -> torch.Tensor:
    """Many controllers at once.

    params [N, P] (one controller per candidate); z [N, R, Z], h [N, R, H] (R rollouts each).
    Returns model-space actions: indices [N, R] (discrete) or [N, R, A] in [-1, 1] (continuous).
    """
    n, a = params.shape[0], spec.action_dim
    width = params.shape[1] // a - 1  # F: what this controller reads
    if width == z.shape[-1]:
        feat = z  # [N, R, Z]: the controller on z alone
    elif width == z.shape[-1] + h.shape[-1]:
        feat = torch.cat([z, h], -1)  # [N, R, Z+H]
    else:
        raise ValueError(f"a controller of {params.shape[1]} parameters does not read z ({z.shape[-1]}) or [z, h]")
    w = params[:, : a * feat.shape[-1]].reshape(n, a, feat.shape[-1])  # [N, A, Z+H]
    b = params[:, a * feat.shape[-1]:]  # [N, A]
    out = torch.einsum("nrf,naf->nra", feat, w) + b[:, None]  # [N, R, A]
    return out.argmax(-1) if spec.discrete else torch.tanh(out)
