"""The critic replay loss: lambda-returns over replayed data, against a slow reference, and its effect."""
import numpy as np
import pytest
import torch

from dreamer_loop import tiny_config
from wmdist.algos.dreamer import Dreamer
from wmdist.algos.dreamer.replay_value import replay_lambda_returns
from wmdist.bench.dreamer import bench_spec, random_batch


def reference(reward, terminal, first, valid, value, gamma, lam):
    """Per row, backwards over the steps with explicit episode bookkeeping (slow, obvious)."""
    b, t_len = reward.shape
    out = np.zeros((b, t_len))
    for i in range(b):
        for t in reversed(range(t_len)):
            follows = t + 1 < t_len and valid[i, t] and valid[i, t + 1] and not first[i, t + 1]
            if not follows:
                out[i, t] = value[i, t]
                continue
            c = 0.0 if terminal[i, t + 1] else 1.0
            out[i, t] = reward[i, t + 1] + gamma * c * ((1 - lam) * value[i, t + 1] + lam * out[i, t + 1])
    return out


@pytest.mark.parametrize("lam", [0.0, 0.95, 1.0])
def test_replay_returns_match_reference(lam):
    rng = np.random.default_rng(1)
    b, t_len = 5, 12
    reward = rng.normal(size=(b, t_len))
    value = rng.normal(size=(b, t_len))
    first = rng.random((b, t_len)) < 0.15
    first[:, 0] = True
    terminal = np.zeros((b, t_len), bool)
    for i, t in zip(*np.nonzero(first)):  # the step before a new episode may be a terminal
        if t > 0 and rng.random() < 0.6:
            terminal[i, t - 1] = True
    valid = np.ones((b, t_len), bool)
    valid[0, 9:] = False  # padding at a window's end
    ours = replay_lambda_returns(*(torch.tensor(x) for x in (reward, terminal, first, valid, value)), 0.9, lam)
    np.testing.assert_allclose(ours.numpy(), reference(reward, terminal, first, valid, value, 0.9, lam), rtol=1e-10, atol=1e-10)


def test_replay_returns_count_steps_to_a_terminal():
    # gamma = lam = 1, reward 1, values 0: R_t is the number of rewards left before the terminal
    reward = torch.ones(1, 6)
    terminal = torch.tensor([[False, False, False, True, False, False]])
    first = torch.tensor([[True, False, False, False, True, False]])
    valid = torch.ones(1, 6, dtype=torch.bool)
    out = replay_lambda_returns(reward, terminal, first, valid, torch.zeros(1, 6), 1.0, 1.0)
    assert out[0, :3].tolist() == [3.0, 2.0, 1.0]
    assert out[0, 3] == 0.0 and out[0, 5] == 0.0  # a terminal, a window's end: the annotation


def _terminating_batch(spec, b, t_len):
    batch = random_batch(spec, b, t_len, seed=3)
    batch["reward"][:] = 1.0
    batch["reward"][:, 0] = 0.0
    batch["terminal"][:, -1] = True  # every window ends in a real termination
    batch["last"][:, -1] = True
    return batch


def _value_before_end(repval: float, updates: int = 40) -> tuple[float, float, dict]:
    spec = bench_spec(True)
    # no continue head: imagination never ends, so only the replay loss can tell the critic
    cfg = tiny_config(3, cont_head=False, discount=0.9, repval_scale=repval, critic_lr=1e-2)
    learner = Dreamer(spec, cfg).make_learner()
    batch = _terminating_batch(spec, 4, 8)
    for _ in range(updates):
        metrics = learner.update(batch).metrics
    t = learner._tensors(batch)
    with torch.no_grad():
        _, _, start = learner.world_model_loss(t)
        v = learner.ac_loss._value(learner.ac.critic({"h": start.deter, "z": start.latent})["critic"]).reshape(4, 8)
    return float(v[:, -2].mean()), float(v[:, 1].mean()), metrics


def test_replay_loss_teaches_the_critic_a_real_termination():
    pre_on, early_on, metrics = _value_before_end(1.0)
    pre_off, early_off, _ = _value_before_end(0.0)
    assert "repval_loss" in metrics and np.isfinite(metrics["repval_loss"])
    # true returns: 1 one step before the end, ~4.7 six steps before it (gamma 0.9). Imagination
    # without a continue head never ends, so only the replay loss can order the two.
    assert early_on - pre_on > 1.0
    assert abs(early_off - pre_off) < 0.2
