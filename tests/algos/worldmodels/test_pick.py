"""The published controller is the best re-evaluated candidate: a lucky single score does not
win, the pick only changes for a better re-score, it survives a checkpoint, and the learner
publishes it when `reeval_every` is set."""
import io

import numpy as np
import torch

from wmdist.algos.worldmodels import WorldModels, WorldModelsConfig
from wmdist.algos.worldmodels.pick import ControllerPick
from wmdist.runtime.checkpoint import _tensorise

from tests.algos.worldmodels.test_learner import SMALL, SPEC, _batch


def _noisy(true_f: dict[float, float], rollouts: int, rng: np.random.Generator):
    """Fitness of [N, 1] candidates: their true value (keyed by x) plus noise averaged over `rollouts`."""
    def evaluate(x: np.ndarray) -> np.ndarray:
        return np.array([true_f[float(v)] + rng.normal(0, 100, rollouts).mean() for v in x[:, 0]])
    return evaluate


def test_the_re_evaluated_best_is_kept_and_only_replaced_by_a_better_one():
    pick = ControllerPick(1)
    assert not pick.has
    true_f = {0.0: 500.0, 1.0: 300.0, 2.0: 700.0}
    rng = np.random.default_rng(0)
    # a single rollout each would often rank 1.0 above 0.0; 400 rollouts put the noise at 5
    f = pick.offer(_noisy(true_f, 400, rng), {"mean": np.array([0.0]), "best": np.array([1.0])})
    assert f.shape == (2,) and pick.has and pick.source == "mean" and pick.x[0] == 0.0
    assert abs(pick.f - 500) < 25
    pick.offer(_noisy(true_f, 400, rng), {"mean": np.array([1.0]), "best": np.array([1.0])})
    assert pick.x[0] == 0.0  # a worse re-score leaves the pick alone
    pick.offer(_noisy(true_f, 400, rng), {"mean": np.array([1.0]), "best": np.array([2.0])})
    assert pick.x[0] == 2.0 and pick.source == "best" and abs(pick.f - 700) < 25
    again = ControllerPick(1)
    again.load({k: torch.as_tensor(np.atleast_1d(v)) for k, v in pick.state().items()})
    assert again.x[0] == 2.0 and again.f == pick.f and again.source == "best"


def test_the_learner_publishes_the_pick_and_resumes_it():
    algo = WorldModels(SPEC, WorldModelsConfig(**SMALL, reeval_every=2, reeval_rollouts=3))
    learner = algo.make_learner()
    metrics = [learner.update(_batch(i)).metrics for i in range(7)]  # V, V, M, M, then 3 generations
    assert "reeval_mean" not in metrics[4] and "reeval_mean" in metrics[5] and "reeval_mean" not in metrics[6]
    # the pick is reported from its first re-evaluation on, every generation (a driver tick logs one update)
    assert "pick_fitness" not in metrics[4] and metrics[6]["pick_fitness"] == metrics[5]["pick_fitness"]
    assert metrics[5]["pick_fitness"] == max(metrics[5]["reeval_mean"], metrics[5]["reeval_gen_best"])
    # the console's figure is the published controller's score: the best-ever candidate's until a pick exists
    assert metrics[4]["headline_fitness"] == metrics[4]["cma_best_fitness"]
    assert metrics[5]["headline_fitness"] == metrics[6]["headline_fitness"] == metrics[5]["pick_fitness"]
    np.testing.assert_array_equal(learner.get_weights()["controller"], learner.pick.x.astype(np.float32))
    assert not np.array_equal(learner.pick.x, learner.cma.best_x) or learner.pick.source == "best"
    buf = io.BytesIO()
    torch.save(_tensorise(learner.state_dict()), buf)
    buf.seek(0)
    again = algo.make_learner()
    again.load_state_dict(torch.load(buf, weights_only=True))
    np.testing.assert_array_equal(again.get_weights()["controller"], learner.get_weights()["controller"])
    assert again.pick.f == learner.pick.f


def test_without_re_evaluation_the_best_ever_candidate_is_published():
    learner = WorldModels(SPEC, WorldModelsConfig(**SMALL)).make_learner()
    for i in range(6):
        metrics = learner.update(_batch(i)).metrics
    assert "pick_fitness" not in metrics and not learner.pick.has
    assert metrics["headline_fitness"] == metrics["cma_best_fitness"]
    np.testing.assert_array_equal(learner.get_weights()["controller"], learner.cma.best_x.astype(np.float32))
