"""The continue loss's terminal weight (`algo.cont_terminal_weight`): the loss against a hand
computation from the model's own continue logits, and its effect on a rare terminal."""
import numpy as np
import torch
import torch.nn.functional as F

from dreamer_loop import tiny_config
from wmdist.algos.dreamer import Dreamer
from wmdist.algos.dreamer.nets import action_to_model
from wmdist.bench.dreamer import bench_spec, random_batch


def _batch(spec, terminal_rows: int):
    batch = random_batch(spec, 6, 8, seed=5)
    batch["terminal"][:terminal_rows, -1] = True  # a few windows end in a real termination
    batch["last"][:terminal_rows, -1] = True
    return batch


def _wm_loss_and_cont_logits(learner, batch):
    """The world-model loss and the continue head's logits [B, T], on the same posterior draws."""
    learner.generator.manual_seed(11)
    t = learner._tensors(batch)
    with torch.no_grad():
        loss, _, _ = learner.world_model_loss(t)
        learner.generator.manual_seed(11)
        wm = learner.wm
        out = wm.rssm.observe(wm.encode(t["obs"]), action_to_model(t["action"], learner.spec), t["first"].bool(),
                              learner.generator)
        logits = wm.heads({"h": out.deter.flatten(0, 1), "z": out.latent})["cont"].reshape(t["mask"].shape)
    return float(loss), logits


def test_terminal_steps_count_weight_times_in_the_continue_loss():
    spec = bench_spec(True)
    learner = Dreamer(spec, tiny_config(3, cont_scale=2.0)).make_learner()
    batch = _batch(spec, 2)
    plain, logits = _wm_loss_and_cont_logits(learner, batch)
    learner.cfg.cont_terminal_weight = 5.0
    weighted, _ = _wm_loss_and_cont_logits(learner, batch)
    term = torch.as_tensor(batch["terminal"])
    bce_terminal = F.binary_cross_entropy_with_logits(logits[term], torch.zeros(int(term.sum())), reduction="sum")
    want = 2.0 * (5.0 - 1.0) * float(bce_terminal) / batch["mask"].sum()  # cont_scale x extra weight / real steps
    np.testing.assert_allclose(weighted - plain, want, rtol=1e-4)
    # no terminal in the batch: the weight changes nothing
    none = _batch(spec, 0)
    learner.cfg.cont_terminal_weight = 1.0
    a, _ = _wm_loss_and_cont_logits(learner, none)
    learner.cfg.cont_terminal_weight = 5.0
    b, _ = _wm_loss_and_cont_logits(learner, none)
    assert a == b


def _terminal_prob_after_training(weight: float, updates: int = 100) -> float:
    spec = bench_spec(True)
    torch.manual_seed(0)
    learner = Dreamer(spec, tiny_config(3, cont_terminal_weight=weight)).make_learner()
    batch = _batch(spec, 1)  # 1 terminal among 48 steps
    for _ in range(updates):
        learner.update(batch)
    _, logits = _wm_loss_and_cont_logits(learner, batch)
    return float(1.0 - torch.sigmoid(logits[0, -1]))


def test_a_heavier_terminal_weight_teaches_a_rare_end_sooner():
    # with weight 1 the head learns "always continue" (0.14 at the end after 100 updates), with 20 it keeps ~0.4
    assert _terminal_prob_after_training(20.0) > _terminal_prob_after_training(1.0) + 0.2
