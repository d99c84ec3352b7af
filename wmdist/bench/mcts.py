"""Batched MCTS throughput: the tree alone and with a real MLP model, against the reference.

Cases: B in {1, 8, 64, 256} roots, A in {2, 18} actions, 50 simulations, pUCT.
- kind "tree": recurrent_fn returns pre-generated outputs (a table lookup), so the time
  is the engine's (selection, expansion, backup, latent store, Python loop).
  `vs_reference` = its simulations/s over the plain-Python reference search's, measured
  in the same run on the same pre-generated outputs.
- kind "mlp": a torch MLP world model (latent 64, hidden 128, one thread);
  `tree_fraction` = share of search time outside recurrent_fn, and `forward_per_s` the
  raw batched forward passes/s of the same model at that B (the network's limit).
Times are the best of several repeats (robust to other processes on the machine).
"""
from __future__ import annotations

import time
from typing import Callable, Iterator

import numpy as np
import torch
from torch import nn

from wmdist.search.api import SearchConfig, search
from wmdist.search.reference import reference_search

SIMS = 50
LATENT, HIDDEN = 64, 128


class _Pregenerated:
    """recurrent_fn replaying random outputs prepared in advance (latent [B, 8] float32)."""

    def __init__(self, batch: int, num_actions: int, rng: np.random.Generator) -> None:
        self.reward = rng.normal(size=(SIMS, batch))
        self.value = rng.normal(size=(SIMS, batch))
        self.logits = rng.normal(size=(SIMS, batch, num_actions))
        self.latent = np.zeros((batch, 8), dtype=np.float32)
        self.s = 0

    def __call__(self, latents, actions):
        s = self.s % SIMS
        self.s += 1
        return self.reward[s], self.value[s], self.logits[s], latents

    def step(self, latent, action):  # one-root adapter for the reference search
        s = self.s % SIMS
        self.s += 1
        return self.reward[s, 0], self.value[s, 0], self.logits[s, 0], latent


class _MLPModel(nn.Module):
    """MuZero-style dynamics g(s, a) -> (r, s') and prediction f(s') -> (v, logits) as MLPs."""

    def __init__(self, num_actions: int) -> None:
        super().__init__()
        self.num_actions = num_actions
        self.dynamics = nn.Sequential(nn.Linear(LATENT + num_actions, HIDDEN), nn.ReLU(), nn.Linear(HIDDEN, LATENT + 1))
        self.prediction = nn.Sequential(nn.Linear(LATENT, HIDDEN), nn.ReLU(), nn.Linear(HIDDEN, num_actions + 1))

    def forward(self, latent: torch.Tensor, actions: torch.Tensor):
        onehot = nn.functional.one_hot(actions, self.num_actions).to(latent.dtype)
        out = self.dynamics(torch.cat([latent, onehot], dim=1))
        nxt, reward = out[:, :LATENT], out[:, LATENT]
        pred = self.prediction(nxt)
        return reward, pred[:, 0], pred[:, 1:], nxt


def _best_time(fn: Callable[[], None], repeats: int, min_total: float) -> float:
    best = float("inf")
    start = time.perf_counter()
    for i in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
        if i >= 2 and time.perf_counter() - start > min_total:
            break
    return best


def _roots(batch: int, num_actions: int, rng: np.random.Generator):
    return rng.normal(size=(batch, num_actions)), rng.normal(size=batch), np.ones((batch, num_actions), dtype=bool)


def _tree_case(batch: int, num_actions: int, ref_rate: float, repeats: int) -> dict:
    rng = np.random.default_rng(0)
    model = _Pregenerated(batch, num_actions, rng)
    logits, value, legal = _roots(batch, num_actions, rng)
    config = SearchConfig(num_simulations=SIMS)
    search_rng = np.random.default_rng(1)

    def once():
        search(model.latent, logits, value, legal, None, model, config, search_rng)

    once()  # compile / warm up
    best = _best_time(once, repeats, min_total=1.0)
    rate = batch * SIMS / best
    return {"kind": "tree", "B": batch, "A": num_actions, "sims": SIMS, "sims_per_s": round(rate),
            "ms_per_search": round(best * 1e3, 3), "reference_sims_per_s": round(ref_rate),
            "vs_reference": round(rate / ref_rate, 1)}


def _reference_rate(num_actions: int) -> float:
    rng = np.random.default_rng(0)
    model = _Pregenerated(1, num_actions, rng)
    logits, value, legal = _roots(1, num_actions, rng)
    config = SearchConfig(num_simulations=SIMS)
    zeros = np.zeros(num_actions)

    def once():
        reference_search(model.latent[0], logits[0], value[0], legal[0], model.step, config, zeros, zeros, False)

    return SIMS / _best_time(once, 20, min_total=0.5)


def _mlp_case(batch: int, num_actions: int, repeats: int) -> dict:
    torch.manual_seed(0)
    net = _MLPModel(num_actions).eval()
    rng = np.random.default_rng(0)
    logits, value, legal = _roots(batch, num_actions, rng)
    root = torch.randn(batch, LATENT)
    config = SearchConfig(num_simulations=SIMS)
    search_rng = np.random.default_rng(1)
    model_time = [0.0]

    def recurrent_fn(latents, actions):
        t0 = time.perf_counter()
        with torch.no_grad():
            r, v, lg, nxt = net(latents, torch.from_numpy(actions))
        out = r.numpy(), v.numpy(), lg.numpy(), nxt
        model_time[0] += time.perf_counter() - t0
        return out

    def once():
        model_time[0] = 0.0
        search(root, logits, value, legal, None, recurrent_fn, config, search_rng)

    once()
    best, best_share = float("inf"), 1.0
    for _ in range(repeats):
        t0 = time.perf_counter()
        once()
        elapsed = time.perf_counter() - t0
        if elapsed < best:
            best, best_share = elapsed, 1.0 - model_time[0] / elapsed
    actions = torch.zeros(batch, dtype=torch.long)

    def forwards():
        with torch.no_grad():
            for _ in range(SIMS):
                net(root, actions)

    fwd = _best_time(forwards, repeats, min_total=0.5)
    return {"kind": "mlp", "B": batch, "A": num_actions, "sims": SIMS, "sims_per_s": round(batch * SIMS / best),
            "ms_per_search": round(best * 1e3, 3), "tree_fraction": round(best_share, 3),
            "forward_per_s": round(SIMS / fwd), "searches_per_s_vs_forward_limit": round(fwd / best, 3)}


def run(quick: bool = False) -> Iterator[dict]:
    """One dict per case; quick=True runs B in {1, 64}, A = 18 only."""
    torch_threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        batches = (1, 64) if quick else (1, 8, 64, 256)
        actions = (18,) if quick else (2, 18)
        repeats = 5 if quick else 15
        for num_actions in actions:
            ref_rate = _reference_rate(num_actions)
            for batch in batches:
                yield _tree_case(batch, num_actions, ref_rate, repeats)
            for batch in batches:
                yield _mlp_case(batch, num_actions, repeats)
    finally:
        torch.set_num_threads(torch_threads)
