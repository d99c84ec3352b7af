"""Scoring controllers: whole batches of candidates in M's dream, or in the real env (several envs
in lockstep in `real_returns`; tests/algos/worldmodels/test_real_rollouts.py keeps the plain
one-episode-at-a-time reference).

Dream (World Models, sec. 4.4, the Doom experiment): from an initial latent z_0 (a real first
frame's encoding), C acts on [z_t, h_t], M samples z_{t+1} from its mixture at temperature tau
and a done flag from its done head; the fitness is the number of steps survived (Take Cover's
reward, +1 per step), so the dream serves survival tasks. A candidate's score is the mean over
its R rollouts; every candidate of a generation sees the same R seeds (common random numbers).
"""
from __future__ import annotations

from typing import Any

import numpy as np
import torch

from wmdist.algos.worldmodels.controller import act_batched
from wmdist.algos.worldmodels.mdn import MDNRNN, mdn_sample
from wmdist.algos.worldmodels.vae import ConvVAE
from wmdist.envs.spec import EnvSpec
from wmdist.nets.actions import action_to_env, action_to_model


@torch.no_grad()
def dream_fitness(
    params: torch.Tensor,  # [N, P] candidates
    z0: torch.Tensor,  # [N, R, Z] initial latents, one per rollout
    rnn: MDNRNN,
    spec: EnvSpec,
    tau: float,
    max_steps: int,
    generator: torch.Generator | None = None,
) -> np.ndarray:
    """Mean steps survived [N] over the R dream rollouts of each candidate."""
    n, r, z_dim = z0.shape
    z = z0
    state = rnn.initial(n * r, z0.device)
    alive = torch.ones(n, r, dtype=torch.bool, device=z0.device)
    steps = torch.zeros(n, r, device=z0.device)
    for _ in range(max_steps):
        h = state[0][0].reshape(n, r, -1)  # [N, R, H]
        a = act_batched(params, z, h, spec)  # [N, R] or [N, R, A] model-space
        a_in = action_to_model(a, spec) if spec.discrete else a  # one-hot, or already in [-1, 1]
        log_pi, mu, log_sigma, done_logit, state = rnn.step(z.reshape(n * r, z_dim), a_in.reshape(n * r, -1), state)
        z = mdn_sample(log_pi, mu, log_sigma, tau, generator).reshape(n, r, z_dim)
        steps += alive.float()
        done = torch.bernoulli(torch.sigmoid(done_logit), generator=generator).bool().reshape(n, r)
        alive &= ~done
        if not alive.any():
            break
    return steps.mean(1).cpu().numpy().astype(np.float64)


@torch.no_grad()
def real_returns(
    params: torch.Tensor,  # [J, P] one candidate per episode
    envs: list[Any],  # >= J wmdist Envs, stepped in lockstep
    vae: ConvVAE,
    rnn: MDNRNN,
    spec: EnvSpec,
    seeds: np.ndarray,  # [J] each episode's env seed
    max_steps: int | None = None,
    patience: int = 0,
) -> np.ndarray:
    """[J] returns of J real episodes at once, each z_t = V's mean of o_t and h_t from M, with one
    batched V and M call per step for all of them (the env steps stay one by one). An episode ends
    at the env's end, at `max_steps`, or after `patience` steps in a row without a positive reward."""
    j = params.shape[0]
    obs = np.stack([envs[i].reset(int(seeds[i])) for i in range(j)])  # [J, H, W, C]
    h, c = rnn.initial(j)  # [1, J, H] each
    total, steps = np.zeros(j), 0
    idle = np.zeros(j, int)  # [J] steps in a row without a positive reward
    live = np.ones(j, bool)
    while live.any():
        idx = np.flatnonzero(live)
        sel = torch.as_tensor(idx)
        mu, _ = vae.encode(torch.as_tensor(obs[idx]))  # [L, Z]
        a = act_batched(params[sel], mu[:, None], h[0, sel][:, None], spec)[:, 0]  # [L] or [L, A]
        env_a = action_to_env(a, spec)
        steps += 1
        for k, i in enumerate(idx):
            o, reward, term, trunc = envs[i].step(env_a[k])
            obs[i] = o
            total[i] += reward
            idle[i] = 0 if reward > 0 else idle[i] + 1
            if term or trunc or (max_steps and steps >= max_steps) or (patience and idle[i] >= patience):
                live[i] = False
        a_in = action_to_model(torch.as_tensor(np.asarray(env_a)), spec)  # [L, A]
        _, _, _, _, (h_l, c_l) = rnn.step(mu, a_in, (h[:, sel], c[:, sel]))
        h, c = h.index_copy(1, sel, h_l), c.index_copy(1, sel, c_l)
    return total
