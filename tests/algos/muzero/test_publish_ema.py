"""algo.publish_ema: the published weights are a Polyak average of the learner's, equal to a
plain per-update loop, kept across a checkpoint, and the learner's own when the decay is 0."""
import numpy as np
import torch

from tests.algos.efficientzero.common import small_algo
from tests.algos.muzero.helpers import random_batch


def _own(learner) -> dict[str, np.ndarray]:
    return {k: v.detach().numpy().copy() for k, v in learner.net.state_dict().items()}


def test_published_weights_are_the_average_of_a_plain_loop():
    decay = 0.8
    learner = small_algo(publish_ema=decay).make_learner()
    ref = _own(learner)  # the average starts at the initial weights
    buffers = {k for k, _ in learner.net.named_buffers()}
    assert buffers  # the check below covers both kinds of tensor
    rng = np.random.default_rng(0)
    for _ in range(4):
        learner.update(random_batch(rng, 8, 12, 3))
        own = _own(learner)
        # parameters averaged; buffers (the projector's BatchNorm statistics) are the learner's own
        ref = {k: own[k] if k in buffers else decay * ref[k] + (1 - decay) * own[k] for k in ref}
    pub = learner.get_weights()
    assert set(pub) == set(ref)
    for k in ref:
        np.testing.assert_allclose(pub[k], ref[k], rtol=1e-5, atol=1e-6)
    # the average lags: it is not the learner's own weights after 4 updates of decay 0.8
    own = _own(learner)
    assert max(float(np.abs(pub[k] - own[k]).max()) for k in own) > 1e-4


def test_zero_decay_publishes_the_learner_weights_and_the_average_survives_a_checkpoint():
    rng = np.random.default_rng(1)
    plain = small_algo().make_learner()
    plain.update(random_batch(rng, 8, 12, 3))
    for k, v in _own(plain).items():
        np.testing.assert_array_equal(plain.get_weights()[k], v)

    a = small_algo(publish_ema=0.9).make_learner()
    for _ in range(3):
        a.update(random_batch(rng, 8, 12, 3))
    state = a.state_dict()
    b = small_algo(publish_ema=0.9).make_learner()
    b.load_state_dict(state)
    for k, v in a.get_weights().items():
        np.testing.assert_array_equal(b.get_weights()[k], v)
    batch = random_batch(np.random.default_rng(2), 8, 12, 3)
    torch.manual_seed(0); a.update(batch)
    torch.manual_seed(0); b.update(batch)
    for k, v in a.get_weights().items():
        np.testing.assert_allclose(b.get_weights()[k], v, rtol=1e-6, atol=1e-7)
    # a checkpoint written without the average (publish_ema was 0) starts it at the weights
    c = small_algo(publish_ema=0.9).make_learner()
    c.load_state_dict(plain.state_dict())
    for k, v in _own(plain).items():
        np.testing.assert_array_equal(c.get_weights()[k], v)


def test_publish_ema_to_eval_gives_the_average_to_the_evaluator_alone():
    from wmdist.runtime.calls import LocalHandle, put
    from wmdist.runtime.roles.weights import WeightBroker, pull

    rng = np.random.default_rng(3)
    shared = small_algo(publish_ema=0.8).make_learner()
    ev = small_algo(publish_ema=0.8, publish_ema_to="eval").make_learner()
    ev.load_state_dict(shared.state_dict())
    assert shared.get_eval_weights() is None  # "all": everyone acts on the average
    for _ in range(3):
        batch = random_batch(rng, 8, 12, 3)
        torch.manual_seed(0); shared.update(batch)
        torch.manual_seed(0); ev.update(batch)
    for k, v in _own(ev).items():  # collectors and reanalyzers: the learner's own weights
        np.testing.assert_array_equal(ev.get_weights()[k], v)
    average = ev.get_eval_weights()
    for k, v in shared.get_weights().items():  # the evaluator: the same average "all" publishes
        np.testing.assert_allclose(average[k], v, rtol=1e-6, atol=1e-7)
    # through the broker as the learner role publishes them: one pull each way
    broker = LocalHandle(WeightBroker())
    broker.publish.remote(7, [put(ev.get_weights(), local=True), put(average, local=True)])
    _, actors = pull(broker, -1)
    version, judged = pull(broker, -1, evaluator=True)
    assert version == 7
    k = next(iter(average))
    np.testing.assert_array_equal(actors[k], ev.get_weights()[k])
    np.testing.assert_array_equal(judged[k], average[k])
    broker.publish.remote(8, [put(ev.get_weights(), local=True)])  # no evaluator weights: the shared ones
    np.testing.assert_array_equal(pull(broker, 7, evaluator=True)[1][k], ev.get_weights()[k])
