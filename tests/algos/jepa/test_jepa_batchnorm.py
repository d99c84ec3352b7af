"""The projector's BatchNorm statistics that planning uses (issue 23): the learner re-estimates
them for exactly the weights it publishes, from its latest frames, instead of torch's running
average over older weights."""
from __future__ import annotations

import numpy as np
import torch

from tests.algos.jepa.test_jepa_learning import small_config
from wmdist.algos.jepa import Jepa
from wmdist.algos.jepa.model import JepaModel, load_model, recalibrate_batchnorm
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import env_spec


def _frames(n: int, seed: int) -> torch.Tensor:  # [N, 64, 64, 3] uint8
    return torch.as_tensor(np.random.default_rng(seed).integers(0, 256, (n, 64, 64, 3), dtype=np.uint8))


def _batch(seed: int, b: int = 8, t: int = 4) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {"obs": rng.integers(0, 256, (b, t, 64, 64, 6), dtype=np.uint8),
            "action": rng.uniform(-1, 1, (b, t, 2)).astype(np.float32),
            "mask": np.ones((b, t), np.float32)}


def test_recalibrated_eval_embeddings_equal_the_batch_statistics_ones():
    torch.manual_seed(0)
    model = JepaModel(small_config(), 2)
    frames = _frames(64, 0)
    with torch.no_grad():
        model.train()
        want = model.encode(frames)  # normalised with these frames' own statistics
        model.eval()
        before = model.encode(frames)  # fresh running statistics (0 and 1): far off
        recalibrate_batchnorm(model, frames, chunk=64)
        got = model.encode(frames)
    assert not model.training  # the mode it was in
    assert (before - want).abs().max() > 0.5
    # eval mode divides by the unbiased variance, training by the biased one: 64/63
    torch.testing.assert_close(got, want, rtol=0.02, atol=0.02)
    momenta = {m.momentum for m in model.modules() if isinstance(m, torch.nn.BatchNorm1d)}
    assert momenta == {0.1}  # restored after the cumulative average


def test_published_weights_carry_statistics_of_the_latest_frames_for_those_weights():
    spec = env_spec(EnvConfig(id="nav:open"))
    learner = Jepa(spec, small_config(lr=3e-3), seed=0).make_learner()
    batches = [_batch(s) for s in range(6)]
    for b in batches:
        learner.update(b)
    policy_model = JepaModel(small_config(), spec.action_dim).eval()
    load_model(policy_model, learner.get_weights())
    seen = torch.as_tensor(np.concatenate([b["obs"][..., :3].reshape(-1, 64, 64, 3) for b in batches]))  # [192, ...]
    assert small_config().bn_frames >= 192  # so the learner kept every frame, in order
    assert learner.recent is not None and torch.equal(learner.recent, seen)
    with torch.no_grad():
        learner.model.train()
        want = learner.model.encode(seen)  # one batch: the statistics of exactly these frames and weights
        got = policy_model.encode(seen)
    torch.testing.assert_close(got, want, rtol=0.02, atol=0.02)


def test_without_recalibration_the_running_average_lags_the_weights():
    spec = env_spec(EnvConfig(id="nav:open"))
    learner = Jepa(spec, small_config(lr=3e-3, bn_frames=0), seed=0).make_learner()
    batches = [_batch(s) for s in range(6)]
    for b in batches:
        learner.update(b)
    assert learner.recent is None
    policy_model = JepaModel(small_config(), spec.action_dim).eval()
    load_model(policy_model, learner.get_weights())
    last = torch.as_tensor(batches[-1]["obs"][..., :3].reshape(-1, 64, 64, 3))
    with torch.no_grad():
        learner.model.train()
        want = learner.model.encode(last)
        got = policy_model.encode(last)
    assert (got - want).abs().max() > 0.2  # what the recalibration removes
