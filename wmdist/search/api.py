"""Public API of the batched MCTS engine (MuZero pUCT, Gumbel MuZero, EfficientZero value prefix).

Conventions (shared by the fast engine and `reference.py`):

- Values are from the view of the player to move at the node ("perspective-relative"), as
  the networks see observations from the mover's view. `reward` is the reward of the
  player who took the action. With `two_player=True` the backup flips sign every ply:
  Q(s, a) = r + discount * (-1) * V(s'); otherwise Q(s, a) = r + discount * V(s').
  `to_play` is therefore only validated, never needed by the arithmetic.
- Node visit counts include the node's own expansion: N(s) = 1 + sum_b N(s, b) and a
  node's value is the mean of its network value and every return backed up through it
  (the root starts with `root_value`). pUCT uses N(s) as the parent count, so the first
  simulation already follows the prior.
- Legal masks apply at the root only; interior nodes may pick any action (the model
  was trained to handle them, as in MuZero).
- Unexpanded children count as visited 0 times; their value in pUCT is set by
  `SearchConfig.unvisited_value`.

`recurrent_fn(latents, actions) -> (reward [B], value [B], logits [B, A], next_latents)`;
in value-prefix mode it is called as `recurrent_fn(latents, actions, reset)` with
`reset [B] bool` true where the parent node starts a new value-prefix segment (depth %
lstm_horizon == 0): the model must start its LSTM state from zeros there, and its
`reward` output is the value prefix (cumulative reward since that reset).
Latents are a numpy array, a CPU torch tensor, or a tuple/list (nested) of them, each with
leading dim B. The latents handed to `recurrent_fn` are views into the engine's buffer:
valid during that call only (copy them if you keep them). reward/value/logits come back as
numpy arrays (any float dtype).

Example (a torch MuZero network on the CPU):

    def recurrent_fn(latents, actions):           # latents [B, ...] torch, actions [B] int64 numpy
        with torch.no_grad():
            reward, value, logits, nxt = net.recurrent(latents, torch.from_numpy(actions))
        return reward.numpy(), value.numpy(), logits.numpy(), nxt
    out = search(root_latent, root_logits, root_value, legal, to_play, recurrent_fn,
                 SearchConfig(num_simulations=50), rng, temperature=1.0)
    out.action, out.policy, out.root_value          # [B], [B, A], [B]
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import numpy as np

from wmdist.config.fields import MAX_PER_DECISION, param

Latents = Any  # np.ndarray | torch.Tensor | nested tuple/list of them, leading dim B
RecurrentFn = Callable[..., tuple[np.ndarray, np.ndarray, np.ndarray, Latents]]


@dataclass
class SearchConfig:
    """Hyperparameters of one search (defaults: MuZero Atari, docs/reference.md)."""

    num_simulations: int = param(50, "simulations per search (one recurrent_fn call each)", ge=1,
                                 le=MAX_PER_DECISION)
    c1: float = param(1.25, "pUCT exploration constant c1 (MuZero eq. 2)", gt=0)
    c2: float = param(19652.0, "pUCT visit-scaling constant c2 (MuZero eq. 2)", gt=0)
    discount: float = param(0.997, "discount gamma used in the backup G = r + gamma * G", ge=0, le=1)
    dirichlet_alpha: float = param(0.25, "Dirichlet concentration of the root exploration noise", gt=0)
    dirichlet_fraction: float = param(0.25, "weight of the Dirichlet noise in the root prior", ge=0, le=1)
    gumbel: bool = param(False, "Gumbel MuZero root (Gumbel-top-k + sequential halving) instead of pUCT")
    gumbel_max_considered: int = param(16, "Gumbel: actions sampled without replacement at the root (m)", ge=1)
    gumbel_c_visit: float = param(50.0, "Gumbel: c_visit in sigma(q) = (c_visit + max N) * c_scale * q", ge=0)
    gumbel_c_scale: float = param(0.1, "Gumbel: c_scale in sigma(q) = (c_visit + max N) * c_scale * q", gt=0)
    value_prefix: bool = param(False, "EfficientZero: recurrent_fn predicts value prefixes, not rewards")
    lstm_horizon: int = param(5, "EfficientZero: value-prefix segments restart every this many steps", ge=1)
    unvisited_value: str = param(
        "parent",
        "pUCT value of an unvisited child: 'parent' = parent's mean value (min-max normalised), "
        "'zero' = normalised score 0 (MuZero pseudocode)",
        choices=("parent", "zero"),
    )

    def __post_init__(self) -> None:
        checks = {
            "num_simulations": self.num_simulations >= 1,
            "c1": self.c1 > 0,
            "c2": self.c2 > 0,
            "discount": 0 <= self.discount <= 1,
            "dirichlet_alpha": self.dirichlet_alpha > 0,
            "dirichlet_fraction": 0 <= self.dirichlet_fraction <= 1,
            "gumbel_max_considered": self.gumbel_max_considered >= 1,
            "gumbel_c_visit": self.gumbel_c_visit >= 0,
            "gumbel_c_scale": self.gumbel_c_scale > 0,
            "lstm_horizon": self.lstm_horizon >= 1,
            "unvisited_value": self.unvisited_value in ("parent", "zero"),
        }
        for key, ok in checks.items():
            if not ok:
                raise ValueError(f"SearchConfig.{key}={getattr(self, key)!r} is out of range")


@dataclass
class SearchOutput:
    """Result of a batched search; every array has leading dim B."""

    visit_counts: np.ndarray  # [B, A] int64 visits of the root's children (sum = num_simulations)
    policy: np.ndarray  # [B, A] float32 policy target: visit counts at the temperature, or
    #                     the Gumbel improved policy softmax(logits + sigma(completed Q))
    action: np.ndarray  # [B] int64 action to play
    root_value: np.ndarray  # [B] float32 search value of the root (mean over its visits)
    q_values: np.ndarray  # [B, A] float32 root children Q (mover's view); unvisited legal
    #                       actions hold the mixed value v_mix (Gumbel MuZero eq. 33), illegal 0


def search(
    root_latent: Latents,
    root_logits: np.ndarray,  # [B, A]
    root_value: np.ndarray,  # [B]
    legal: np.ndarray,  # [B, A] bool
    to_play: np.ndarray | None,  # [B] int player to move, or None
    recurrent_fn: RecurrentFn,
    config: SearchConfig,
    rng: np.random.Generator,
    temperature: float = 1.0,
    add_noise: bool = True,
    two_player: bool = False,
) -> SearchOutput:
    """Run `config.num_simulations` simulations on B roots at once.

    pUCT mode: Dirichlet noise (if add_noise) on the legal root priors; the action is
    sampled from the visit-count policy at `temperature` (greedy, lowest index on ties, if
    temperature == 0). Gumbel mode: Gumbel noise (zero if not add_noise) drives
    Gumbel-top-k and sequential halving; the action is the paper's A_{n+1} and
    `temperature` is ignored.
    """
    from wmdist.search.engine import run_search  # engine imports numba; keep this module light

    return run_search(
        root_latent, root_logits, root_value, legal, to_play, recurrent_fn, config, rng,
        temperature=temperature, add_noise=add_noise, two_player=two_player,
    )
