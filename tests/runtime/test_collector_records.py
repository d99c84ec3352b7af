"""The collector's stored windows follow the step convention of wmdist/algos/base.py.

A real Collector (MuZero on CartPole) writes into a recording replay; weights come from a
fixed snapshot (the broker is the only fake). CartPole is deterministic, so every stored
transition (obs_t, action_t) -> obs_{t+1} can be replayed in gymnasium: a shifted action,
observation or final-observation record would show up as a mismatch.
"""
from pathlib import Path

import numpy as np
import torch

import wmdist.runtime.roles.collector as collector_mod
from wmdist.config.loader import load_config
from wmdist.envs.factory import env_spec
from wmdist.runtime.roles.setup import build_algorithm

torch.set_num_threads(1)

T, OVERLAP = 20, 5


class RecordingReplay:
    def __init__(self) -> None:
        self.batches = []

    def insert(self, batch, source_id, timeout=None) -> bool:
        self.batches.append(batch)
        return True


def _collect(monkeypatch):
    cfg = load_config(Path(__file__).parents[2] / "configs" / "muzero_cartpole.yaml", [
        "algo.search.num_simulations=4", "actors.envs_per_actor=4", "actors.segment_steps=40",
        f"replay.seq_len={T}", f"replay.overlap={OVERLAP}"])
    spec = env_spec(cfg.env)
    weights = build_algorithm(cfg, spec, 0).make_learner().get_weights()
    monkeypatch.setattr(collector_mod, "pull",
                        lambda broker, known, timeout=30.0: (0, weights) if known < 0 else (0, None))
    replay = RecordingReplay()
    col = collector_mod.Collector(cfg, spec, 0, replay, None)
    env_steps = 0
    for _ in range(3):
        env_steps += col.run_segment(env_steps, 0)["env_steps"]
    assert replay.batches
    data = {k: np.concatenate([b.data[k] for b in replay.batches]) for k in replay.batches[0].data}
    mask = np.concatenate([b.mask for b in replay.batches])
    episode = np.concatenate([b.episode_id for b in replay.batches])
    return data, mask, episode


def test_collector_windows_replay_in_cartpole(monkeypatch):
    import gymnasium as gym

    d, mask, episode = _collect(monkeypatch)
    last, first = d["last"], d["first"]
    env = gym.make("CartPole-v1").unwrapped
    env.reset(seed=0)
    checked = 0
    for i in range(len(mask)):
        n = int(mask[i].sum())
        assert mask[i, :n].all() and not mask[i, n:].any(), "padding only after the real steps"
        assert not first[i, 1:].any(), "a window holds one episode: first only at index 0"
        assert d["reward"][i, 0] == 0.0 or not first[i, 0], "no reward arrives with an episode's first obs"
        assert (d["reward"][i, 1:n] == 1.0).all(), "CartPole pays 1 for every step after the first"
        assert not last[i, :n - 1].any(), "last can only be a window's final real step"
        if last[i, n - 1]:
            assert d["action"][i, n - 1] == 0 and d["search_policy"][i, n - 1].sum() == 0
            x, theta = d["obs"][i, n - 1, 0], d["obs"][i, n - 1, 2]
            assert d["terminal"][i, n - 1] == (abs(x) > 2.4 or abs(theta) > 0.2095), "terminal = failed final obs"
        acting = slice(0, n - 1 if last[i, n - 1] else n)
        np.testing.assert_allclose(d["search_policy"][i, acting].sum(-1), 1.0, atol=1e-5)
        for t in range(n - 1):
            env.state = d["obs"][i, t].astype(np.float64)
            env.steps_beyond_terminated = None  # we set the state by hand: no "stepped after done" warning
            nxt, *_ = env.step(int(d["action"][i, t]))
            np.testing.assert_allclose(nxt, d["obs"][i, t + 1], atol=1e-5,
                                       err_msg=f"window {i} step {t}: obs/action misaligned")
            checked += 1
    assert checked > 200
    assert last.any() and d["terminal"].any()
    # consecutive windows of one episode share `overlap` steps
    shared = 0
    for i in range(len(mask)):
        later = np.flatnonzero((episode == episode[i]) & (np.arange(len(mask)) > i))
        if later.size and mask[i].all():
            j = later[0]
            np.testing.assert_array_equal(d["obs"][j, :OVERLAP], d["obs"][i, T - OVERLAP:])
            shared += 1
    assert shared > 0


def test_random_warm_up_counts_env_steps_and_tells_the_policy(tmp_path):
    """`actors.warmup_random_steps` is env steps (E per batched call), and the policy is told the
    random actions taken in its place (a recurrent policy conditions on them)."""
    from wmdist.runtime.local import LocalSession

    cfg = load_config(str(Path(__file__).parent / "fake.yaml"),
                      [f"run.dir={tmp_path}", "ray.local=true", "actors.num=1", "actors.envs_per_actor=4",
                       "actors.segment_steps=1", "actors.warmup_random_steps=10", "replay.shards=1"])
    session = LocalSession(cfg, tmp_path)
    try:
        col = session.collectors[0]
        told = []
        col.policy.taken = lambda actions: told.append(np.asarray(actions).copy())
        session.collect(2)
        assert col.random_steps_left == 2 and len(told) == 2
        session.collect(2)
        assert col.random_steps_left <= 0 and len(told) == 3  # the third call covers the last 2 steps
        assert all(t.shape == (4,) for t in told)
    finally:
        session.close()
