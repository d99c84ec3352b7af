"""Open-loop prediction video: how well an RSSM world model imagines the future (Dreamer, PlaNet).

The policy plays `context + horizon` real steps. The model filters the first `context`
observations (posterior), then rolls the prior forward with the real actions for `horizon`
steps without seeing any more observations. Each GIF frame shows the real observation
beside the model's decoding. Vector observations become a heat-map strip per frame: rows
are observation dimensions, columns time; top block real, bottom block predicted, a white
column marks where imagination starts.
"""
from __future__ import annotations

from pathlib import Path
from typing import Protocol

import imageio.v2 as imageio
import numpy as np
import torch

from wmdist.algos.base import Policy, Weights
from wmdist.envs.env import Env
from wmdist.envs.spec import EnvSpec
from wmdist.nets.actions import action_to_model
from wmdist.nets.world_model import WorldModel


class RSSMAlgorithm(Protocol):
    """What the video needs of an algorithm: its spec, a policy, and its world model loaded from weights."""

    spec: EnvSpec

    def make_policy(self, device: str = "cpu") -> Policy: ...

    def world_model(self, weights: Weights) -> WorldModel: ...


def play_greedy(algo: RSSMAlgorithm, weights: Weights, env: Env, steps: int,
                seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Real observations [steps, *obs] and the actions taken at them [steps, ...]."""
    policy = algo.make_policy()
    policy.set_weights(weights, 0)
    obs = env.reset(seed)
    first = True
    observations, actions = [], []
    for _ in range(steps):
        a, _ = policy.act(obs[None], np.array([first]), None if env.legal_actions() is None else env.legal_actions()[None],
                          None, explore=False)
        observations.append(obs)
        actions.append(a[0])
        obs, _, term, trunc = env.step(a[0])
        first = False
        if term or trunc:
            break
    return np.stack(observations), np.stack(actions)


@torch.no_grad()
def predict_open_loop(algo: RSSMAlgorithm, weights: Weights, obs: np.ndarray, actions: np.ndarray, context: int,
                      seed: int = 0) -> np.ndarray:
    """Model predictions of every observation [T, *obs]: posterior for t < context, prior after."""
    wm = algo.world_model(weights).eval()
    gen = torch.Generator().manual_seed(seed)
    rssm = wm.rssm
    obs_t = torch.as_tensor(obs)
    act_t = action_to_model(torch.as_tensor(actions), algo.spec)  # [T, A]
    h, z = rssm.initial(1)
    a_prev = torch.zeros(1, act_t.shape[-1])
    preds = []
    for t in range(len(obs)):
        keep = torch.full((1, 1), 0.0 if t == 0 else 1.0)
        h = rssm.img_step(h, z, rssm.action_part(a_prev), keep)
        if t < context:  # sampled latents, as the model itself imagines (the mode can sit on one class)
            z = rssm.sample(rssm.post(h, rssm.embed_part(wm.encode(obs_t[t:t + 1]))), gen, grad=False)
        else:
            z = rssm.prior_sample(h, gen, grad=False)
        pred = wm.target_to_obs(wm.decode(h, z))[0]
        if wm.image:
            pred = (pred * 255).to(torch.uint8)
        preds.append(pred.numpy())
        a_prev = act_t[t:t + 1]
    return np.stack(preds)


def _strip(real: np.ndarray, pred: np.ndarray, upto: int, context: int, scale: int = 8) -> np.ndarray:
    """Heat-map frame [H, W, 3] uint8 of real (top) and predicted (bottom) vectors up to `upto`."""
    import matplotlib

    t_len, d = real.shape
    lim = max(float(np.abs(real).max()), 1e-6)
    canvas = np.full((2 * d + 1, t_len), np.nan)
    canvas[:d, : upto + 1] = real[: upto + 1].T
    canvas[d + 1:, : upto + 1] = pred[: upto + 1].T
    rgb = matplotlib.colormaps["coolwarm"]((np.clip(canvas, -lim, lim) / lim + 1) / 2)[..., :3]
    rgb[np.isnan(canvas)] = 0.0
    rgb[d] = 1.0  # separator row
    if context < t_len:
        rgb[:, context] = np.maximum(rgb[:, context], 0.85)  # imagination starts here
    img = (rgb * 255).astype(np.uint8)
    return np.repeat(np.repeat(img, scale, 0), scale, 1)


def open_loop_video(algo: RSSMAlgorithm, weights: Weights, env: Env, out_path: str, context: int = 5, horizon: int = 45, seed: int = 0) -> str:
    """Write the open-loop GIF to `out_path` and return its path."""
    if context < 1 or horizon < 1:
        raise ValueError(f"context and horizon must be >= 1, got {context} and {horizon}")
    obs, actions = play_greedy(algo, weights, env, context + horizon, seed)
    preds = predict_open_loop(algo, weights, obs, actions, context, seed)
    if algo.spec.obs_kind == "image":
        frames = [np.concatenate([o, p], 1) for o, p in zip(obs, preds)]  # real | model
        frames = [np.repeat(np.repeat(f[..., :3] if f.shape[-1] >= 3 else np.repeat(f, 3, -1), 4, 0), 4, 1) for f in frames]
    else:
        frames = [_strip(obs.astype(np.float32), preds.astype(np.float32), t, context) for t in range(len(obs))]
    path = Path(out_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimsave(path, frames, duration=0.1, loop=0)
    return str(path)
