"""The collapse ablation in its clean form (`algo.proj_out_norm=false`): without the projector's
last BatchNorm, nothing but SIGReg holds the embedding's scale up. With no stop-gradient and no EMA
target, the prediction loss alone is minimised by shrinking every embedding toward one point; SIGReg
pushes the batch toward a unit Gaussian instead. Trained on the runtime's own collected data."""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from tests.algos.jepa.test_jepa_learning import small_config
from tests.algos.local_config import local_run_config
from wmdist.algos.jepa import Jepa
from wmdist.algos.jepa.model import JepaModel
from wmdist.envs.config import EnvConfig
from wmdist.envs.factory import env_spec
from wmdist.runtime.local import LocalSession


def _embed_std(sigreg_weight: float) -> tuple[float, float]:
    """Mean per-dimension std of the embeddings on fixed batches, before and after 180 updates."""
    env_cfg = EnvConfig(id="nav:open")
    algo = Jepa(env_spec(env_cfg), small_config(proj_out_norm=False, sigreg_weight=sigreg_weight), seed=0)
    session = LocalSession(local_run_config(algo, env_cfg, num_envs=4, seq_len=6, overlap=3, seed=0, batch_size=8))
    try:
        session.collect(150)
        fixed = [session.sample(16) for _ in range(3)]

        def std() -> float:
            with torch.no_grad():
                return float(np.mean([session.learner.loss(b)[1]["embed_std"] for b in fixed]))

        start = std()
        session.train(180)
        return start, std()
    finally:
        session.close()


def test_the_projector_ends_with_a_batchnorm_unless_switched_off():
    with_bn = JepaModel(small_config(), action_dim=2).projector.net
    without = JepaModel(small_config(proj_out_norm=False), action_dim=2).projector.net
    assert isinstance(with_bn[-1], nn.BatchNorm1d) and isinstance(without[-1], nn.Linear)
    assert without[-1].bias is not None  # no BatchNorm after it to supply the shift


def test_without_the_last_batchnorm_the_embeddings_shrink_unless_sigreg_holds_them():
    start, no_sigreg = _embed_std(0.0)
    same_start, with_sigreg = _embed_std(0.09)
    assert start == same_start  # the same seed, data and initial weights
    assert no_sigreg < 0.3 * start, (start, no_sigreg)  # collapsing toward a point
    assert with_sigreg > 2.0 * start and with_sigreg > 0.5, (start, with_sigreg)  # toward unit variance
