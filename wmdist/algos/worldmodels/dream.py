"""`wmdist dream` for World Models: real frames beside V's reconstruction of M's open-loop
prediction. The first `context` frames are encoded by V (M reads them); after that M feeds
itself: z_{t+1} is sampled from its mixture at temperature tau and decoded by V."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from wmdist.algos.base import Weights
from wmdist.algos.dream_video import play_greedy
from wmdist.algos.worldmodels.mdn import mdn_sample
from wmdist.envs.env import Env
from wmdist.nets.actions import action_to_model


@torch.no_grad()
def predict_frames(algo, weights: Weights, obs: np.ndarray, actions: np.ndarray, context: int, seed: int = 0) -> np.ndarray:
    """uint8 [T, 64, 64, C]: V's decoding of z_t (encoded for t < context, M's samples after)."""
    from wmdist.algos.worldmodels.models import build_rnn, build_vae, load_numpy

    vae, rnn = build_vae(algo.cfg, algo.spec).eval(), build_rnn(algo.cfg, algo.spec).eval()
    load_numpy(vae, weights, "vae")
    load_numpy(rnn, weights, "rnn")
    gen = torch.Generator().manual_seed(seed)
    act = action_to_model(torch.as_tensor(actions), algo.spec)  # [T, A]
    state, z, out = rnn.initial(1), None, []
    for t in range(len(obs)):
        if t < context:
            z, _ = vae.encode(torch.as_tensor(obs[t:t + 1]))  # [1, Z]
        out.append((vae.decode(z)[0] * 255).round().to(torch.uint8).numpy())
        log_pi, mu, log_s, _, state = rnn.step(z, act[t:t + 1], state)
        z = mdn_sample(log_pi, mu, log_s, algo.cfg.temperature, gen)
    return np.stack(out)


def world_models_video(algo, weights: Weights, env: Env, path: str, context: int = 5, horizon: int = 45) -> str:
    if context < 1 or horizon < 1:
        raise ValueError(f"context and horizon must be >= 1, got {context} and {horizon}")
    import imageio.v2 as imageio

    obs, actions = play_greedy(algo, weights, env, context + horizon, 0)
    preds = predict_frames(algo, weights, obs, actions, context)
    frames = [np.repeat(np.repeat(np.concatenate([o, p], 1)[..., :3], 4, 0), 4, 1) for o, p in zip(obs, preds)]
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    imageio.mimsave(out, frames, duration=0.1, loop=0)
    return str(out)
