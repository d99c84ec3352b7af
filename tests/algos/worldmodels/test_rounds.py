"""Iterative training (paper sec. 5): rounds of the controller search with M refitted between
them; the pool's model id moves with M, the old M's scores are dropped, the search goes on from
its mean, and a resumed learner is in the same round."""
import io

import numpy as np
import pytest
import torch

from wmdist.algos.worldmodels import WorldModels, WorldModelsConfig
from wmdist.algos.worldmodels.learner import STAGE_CMA, STAGE_DONE, STAGE_RNN, STAGE_VAE
from wmdist.runtime.checkpoint import _tensorise

from tests.algos.worldmodels.test_learner import SMALL, SPEC, _batch

ROUNDS = dict(SMALL, iterations=2, generations=2, refit_updates=2, reeval_every=1, reeval_rollouts=2)


def test_rounds_of_search_with_m_refitted_between_them():
    algo = WorldModels(SPEC, WorldModelsConfig(**ROUNDS))
    learner = algo.make_learner()
    stages, ids, rnn_before = [], [], None
    for i in range(11):
        stages.append(learner.stage)
        ids.append(learner.model_id)
        if i == 6:  # the first refit update: the old M's scores are gone, its published pick stays
            rnn_before = {k: v.clone() for k, v in learner.rnn.state_dict().items()}
            published = learner.get_weights()["controller"].copy()
            mean = learner.cma.mean.copy()
        m = learner.update(_batch(i)).metrics
        if i == 6:
            assert learner.cma.best_f == -np.inf and learner.pick.f == -np.inf and learner.pick.has
            np.testing.assert_array_equal(learner.get_weights()["controller"], published)
            assert "rnn_nll" in m and m["search_round"] == 0
    assert stages == [STAGE_VAE] * 2 + [STAGE_RNN] * 2 + [STAGE_CMA] * 2 + [STAGE_RNN] * 2 + [STAGE_CMA] * 2 + [STAGE_DONE]
    assert ids[4] == ids[5] and ids[8] == ids[9] == ids[4] + 1  # the pool reloads M for the second round
    assert any(not torch.equal(v, learner.rnn.state_dict()[k]) for k, v in rnn_before.items())  # M was refitted
    assert learner.cma.generation == 4 and learner.pick.f > -np.inf  # re-scored under the new M
    assert not np.allclose(learner.cma.mean, mean)  # the search went on from where it was


def test_a_resumed_learner_is_in_the_same_round():
    algo = WorldModels(SPEC, WorldModelsConfig(**ROUNDS))
    learner = algo.make_learner()
    for i in range(8):
        learner.update(_batch(i))
    buf = io.BytesIO()
    torch.save(_tensorise(learner.state_dict()), buf)
    buf.seek(0)
    again = algo.make_learner()
    again.load_state_dict(torch.load(buf, weights_only=True))
    assert again.stage == learner.stage == STAGE_CMA and again.model_id == learner.model_id
    assert again.update(_batch(9)).metrics["search_round"] == 1


@pytest.mark.parametrize("bad", [dict(generations=0), dict(refit_updates=0)])
def test_rounds_need_a_length_and_a_refit(bad):
    with pytest.raises(ValueError, match="algo.iterations"):
        WorldModelsConfig(**{**ROUNDS, **bad}).validate()
