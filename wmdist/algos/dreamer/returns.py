"""Lambda-returns over an imagined trajectory and DreamerV3's percentile return normaliser."""
from __future__ import annotations

import torch


def lambda_returns(
    reward: torch.Tensor,  # [H, N] r_{t+1}: reward of arriving at imagined state t+1
    cont: torch.Tensor,  # [H, N] gamma * c_{t+1}: discount times continue of state t+1
    value: torch.Tensor,  # [H + 1, N] v(s_t)
    lam: float,
) -> torch.Tensor:
    """R_t = r_{t+1} + gamma c_{t+1} ((1 - lambda) v_{t+1} + lambda R_{t+1}), R_H = v_H -> [H, N].

    (Dreamer eq. 6 / DreamerV3 eq. 7.) The non-recursive part is computed for all t at once.
    """
    h = reward.shape[0]
    if cont.shape[0] != h or value.shape[0] != h + 1:
        raise ValueError(f"lambda_returns: reward {tuple(reward.shape)}, cont {tuple(cont.shape)}, value {tuple(value.shape)} don't line up")
    base = reward + cont * (1 - lam) * value[1:]  # [H, N]
    out = []
    acc = value[-1]
    for t in reversed(range(h)):
        acc = base[t] + cont[t] * lam * acc
        out.append(acc)
    return torch.stack(out[::-1])


class PercentileNormalizer:
    """Tracks EMAs of the P_low and P_high return percentiles (V3: P5, P95, decay 0.99).

    Advantages are divided by max(1, P95 - P5): large returns are scaled down, small ones
    are left alone so that noise in sparse-reward tasks isn't amplified.
    """

    def __init__(self, decay: float = 0.99, low: float = 0.05, high: float = 0.95) -> None:
        if not 0 <= low < high <= 1:
            raise ValueError(f"percentiles must satisfy 0 <= low < high <= 1, got {low}, {high}")
        self.decay, self.q_low, self.q_high = decay, low, high
        self.low = torch.zeros(())
        self.high = torch.zeros(())

    def update(self, returns: torch.Tensor) -> None:
        x = returns.detach().float().flatten()
        lo, hi = torch.quantile(x, torch.tensor([self.q_low, self.q_high], device=x.device)).cpu()
        self.low = self.decay * self.low + (1 - self.decay) * lo
        self.high = self.decay * self.high + (1 - self.decay) * hi

    @property
    def scale(self) -> float:
        return float(self.scale_tensor())

    def scale_tensor(self) -> torch.Tensor:
        """max(1, P_high - P_low) as a 0-d tensor (no host sync inside a compiled graph)."""
        return torch.clamp(self.high - self.low, min=1.0)

    def state_dict(self) -> dict[str, torch.Tensor]:
        return {"low": self.low.clone(), "high": self.high.clone()}

    def load_state_dict(self, state: dict) -> None:
        self.low = torch.as_tensor(state["low"]).clone()
        self.high = torch.as_tensor(state["high"]).clone()
