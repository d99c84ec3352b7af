"""SIGReg on a head above the embedding (`algo.sigreg_head`, LeJEPA's arrangement): SIGReg tests
the head's output, its gradient reaches the head and the encoder, and planning's embeddings and
their BatchNorm statistics do not depend on the head."""
from __future__ import annotations

import numpy as np
import torch

from tests.algos.jepa.test_jepa_batchnorm import _batch, _frames
from tests.algos.jepa.test_jepa_learning import small_config
from wmdist.algos.jepa.learner import JepaLearner
from wmdist.algos.jepa.model import JepaModel, recalibrate_batchnorm
from wmdist.algos.jepa.sigreg import random_directions, sigreg
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import env_spec


def _learner(**kw) -> JepaLearner:
    return JepaLearner(small_config(**kw), env_spec(EnvConfig(id="nav:open")), seed=0)


def test_sigreg_tests_the_heads_output_and_its_gradient_reaches_head_and_encoder():
    learner = _learner(sigreg_head=32, sigreg_head_dim=6, sigreg_weight=1.0)
    model, batch = learner.model, _batch(0)
    assert model.sigreg_head is not None
    # the same statistic by hand, on the head's output (the generator re-seeded to draw the same directions)
    learner.generator.manual_seed(0)
    _, again = learner.loss(batch)
    obs = torch.as_tensor(batch["obs"][..., :3])
    gen = torch.Generator().manual_seed(0)
    z = model.encode(obs).reshape(-1, 8)  # [N, D] every step is real here
    head = model.sigreg_head(z)  # [N, 6]
    want = sigreg(head, random_directions(6, 32, gen), 17, 3.0)
    np.testing.assert_allclose(again["sigreg"], float(want.detach()), rtol=1e-4)
    # SIGReg alone (no predictor loss) trains the head and the encoder, not the predictor
    model.zero_grad()
    z = model.encode(obs).reshape(-1, 8)
    sigreg(model.regularised(z), random_directions(6, 32, gen)).backward()
    assert all(p.grad is not None and float(p.grad.abs().sum()) > 0 for p in model.sigreg_head.parameters())
    assert any(p.grad is not None and float(p.grad.abs().sum()) > 0 for p in model.conv.parameters())
    assert any(p.grad is not None and float(p.grad.abs().sum()) > 0 for p in model.projector.parameters())
    assert all(p.grad is None for p in model.predictor.parameters())


def test_without_a_head_sigreg_tests_the_embedding_as_before():
    model = JepaModel(small_config(), action_dim=2)
    z = torch.randn(16, 8)
    assert model.sigreg_head is None and model.regularised(z) is z


def test_the_head_leaves_planning_embeddings_and_their_statistics_alone():
    torch.manual_seed(0)
    with_head = JepaModel(small_config(sigreg_head=32), action_dim=2)
    torch.manual_seed(0)
    plain = JepaModel(small_config(), action_dim=2)
    plain.load_state_dict({k: v for k, v in with_head.state_dict().items() if not k.startswith("sigreg_head.")})
    frames = _frames(64, 1)
    head_stats = {k: v.clone() for k, v in with_head.sigreg_head.state_dict().items()}
    for m in (with_head, plain):
        recalibrate_batchnorm(m, frames)
        m.eval()
    torch.testing.assert_close(with_head.encode(frames), plain.encode(frames))
    for k, v in with_head.sigreg_head.state_dict().items():  # not on the planning path: not re-estimated
        torch.testing.assert_close(v, head_stats[k])
