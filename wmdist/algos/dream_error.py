"""Open-loop prediction error by horizon: how far ahead an RSSM world model can be trusted.

From every `stride`-th step t of a real episode the model filters o_0..o_t (posterior), rolls its
prior forward with the real actions a_t..a_{t+k-1} and decodes o_{t+k}. The error at horizon k is
the RMS difference from the real o_{t+k}: per observation dimension for vectors (in the env's own
units), over all pixels for images (in [0, 1] units). Beside it stands the same figure for
predicting "no change" (o_t itself): where the model's error is not below that, a planner or an
imagined rollout learns nothing from it that assuming a still world would not give.

Session 35 found PlaNet's cartpole model this way: one step ahead it placed the pole worse than
"no change" did, because a unit-variance decoder on a 5-d state paid less for a wrong angle than
for the KL of encoding the right one (BENCHMARKS.md, PlaNet).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from wmdist.envs.spec import EnvSpec
from wmdist.nets.actions import action_to_model
from wmdist.nets.latent_layers import Latent
from wmdist.nets.world_model import WorldModel


@dataclass
class HorizonError:
    """Squared-error sums at one horizon k over every start that has a real o_{t+k}."""

    horizon: int
    count: int = 0  # starts summed
    model_sq: np.ndarray | None = None  # [D] sum over starts of (prediction - real)^2 (images: D = 1, mean over pixels)
    still_sq: np.ndarray | None = None  # [D] the same for o_t as the prediction ("no change")

    def add(self, model_sq: np.ndarray, still_sq: np.ndarray) -> None:
        """Add per-start squared errors [S, D]."""
        m, s = model_sq.sum(0), still_sq.sum(0)
        self.model_sq = m if self.model_sq is None else self.model_sq + m
        self.still_sq = s if self.still_sq is None else self.still_sq + s
        self.count += model_sq.shape[0]

    def rms(self) -> tuple[np.ndarray, np.ndarray]:
        """(model RMS [D], no-change RMS [D])."""
        assert self.model_sq is not None and self.still_sq is not None and self.count
        return np.sqrt(self.model_sq / self.count), np.sqrt(self.still_sq / self.count)


def _cat(latents: list[Latent]) -> Latent:
    """Rows of single-row latents stacked into one batch."""
    if latents[0].index is not None:
        return Latent(index=torch.cat([z.index for z in latents]), classes=latents[0].classes)
    return Latent(sample=torch.cat([z.sample for z in latents]))


def _draw(rssm, stats: torch.Tensor, generator: torch.Generator | None) -> Latent:
    """A latent from its distribution: sampled with a generator, its mode without one."""
    return rssm.mode(stats) if generator is None else rssm.sample(stats, generator, grad=False)


@torch.no_grad()
def add_episode_errors(wm: WorldModel, spec: EnvSpec, obs: np.ndarray, actions: np.ndarray,
                       errors: dict[int, HorizonError], stride: int = 1,
                       generator: torch.Generator | None = None) -> None:
    """Add one episode's errors at each horizon in `errors` (keys: k >= 1).

    obs [T, *obs_shape] real observations, actions [T, ...] the action taken at each. With a
    generator the latents are sampled (as the model imagines); without one they are the
    posterior and prior modes (deterministic, used by the tests)."""
    rssm, t_len = wm.rssm, len(obs)
    obs_t = torch.as_tensor(obs)
    act = action_to_model(torch.as_tensor(actions), spec)  # [T, A]
    # filtering pass: h_t and z_t ~ q(z_t | h_t, o_t) for every step
    h, z = rssm.initial(1, obs_t.device)
    a_prev = torch.zeros(1, act.shape[-1])
    hs, zs = [], []
    for t in range(t_len):
        keep = torch.full((1, 1), 0.0 if t == 0 else 1.0)
        h = rssm.img_step(h, z, rssm.action_part(a_prev), keep)
        z = _draw(rssm, rssm.post(h, rssm.embed_part(wm.encode(obs_t[t:t + 1]))), generator)
        hs.append(h)
        zs.append(z)
        a_prev = act[t:t + 1]
    starts = np.arange(0, t_len - 1, stride)  # [S] starts with at least one real step after them
    if starts.size == 0:
        return
    h, z = torch.cat([hs[t] for t in starts]), _cat([zs[t] for t in starts])  # [S, D], [S]
    real = obs.astype(np.float32) / (255.0 if wm.image else 1.0)  # [T, *obs] in error units
    now = real[starts]  # [S, *obs] "no change" predictions
    for k in range(1, max(errors) + 1):
        live = starts + k < t_len  # [S] starts whose o_{t+k} is real
        if not live.any():
            break
        # every start keeps rolling (a finished one on the last action, its output unused), so a sampled
        # run draws the same noise whatever the episode's length
        step = torch.as_tensor(np.minimum(starts + k - 1, t_len - 1))
        h = rssm.img_step(h, z, rssm.action_part(act[step]))  # a_{t+k-1} -> h_{t+k}
        z = _draw(rssm, rssm.prior(h), generator)
        if k not in errors:
            continue
        pred = wm.target_to_obs(wm.decode(h, z)).numpy()[live]  # [S', *obs] in error units
        target = real[starts[live] + k]
        sq_model, sq_still = (pred - target) ** 2, (now[live] - target) ** 2
        if wm.image:  # one figure per frame: the mean over pixels and channels
            sq_model, sq_still = sq_model.reshape(len(target), -1).mean(1, keepdims=True), \
                sq_still.reshape(len(target), -1).mean(1, keepdims=True)
        errors[k].add(sq_model, sq_still)


def default_horizons(limit: int) -> list[int]:
    """1, 2, 4, 8, ... up to `limit`, and `limit` itself."""
    ks = [1]
    while ks[-1] * 2 <= limit:
        ks.append(ks[-1] * 2)
    return ks if ks[-1] == limit else ks + [limit]


def format_errors(errors: dict[int, HorizonError], dims: list[str]) -> list[str]:
    """The table `wmdist dream --error` prints: per horizon, each dimension's model RMS over its
    no-change RMS, and the median of those ratios (< 1: the model predicts better than no change).
    The median, because a dimension that hardly moves (a balanced pole's cosine) makes its own
    ratio huge whatever the model does."""
    lines = [f"{'k':>4}{'starts':>8}  " + "".join(f"{d:>16}" for d in dims) + f"{'median ratio':>14}"]
    for k in sorted(errors):
        e = errors[k]
        if not e.count:
            continue
        model, still = e.rms()
        moving = still > 1e-6  # a dimension that never changes has no no-change error to compare with
        ratio = f"{float(np.median(model[moving] / still[moving])):>14.2f}" if moving.any() else f"{'-':>14}"
        cells = "".join(f"{m:>8.3f}/{s:<7.3f}" for m, s in zip(model, still))
        lines.append(f"{k:>4}{e.count:>8}  {cells}{ratio}")
    return lines
