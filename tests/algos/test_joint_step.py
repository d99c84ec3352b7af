"""`joint_step`: one backward over several losses gives each optimiser the gradients its own
backward pass would, and a non-finite loss changes no weight."""
import pytest
import torch

from wmdist.algos.base import NonFiniteLoss
from wmdist.nets.optim import GuardedStep, OptimConfig, joint_step


def _pair(seed: int):
    torch.manual_seed(seed)
    actor, critic = torch.nn.Linear(3, 2), torch.nn.Linear(3, 1)
    cfg = OptimConfig(kind="adam", lr=1e-2, clip_norm=0.5)
    return actor, critic, GuardedStep(actor.parameters(), cfg), GuardedStep(critic.parameters(), cfg)


def _losses(actor, critic, x):
    shared = torch.tanh(x @ torch.ones(3, 3))  # a graph both losses read
    return actor(shared).pow(2).mean(), critic(shared.detach()).pow(2).mean()


def test_one_backward_equals_separate_steps():
    x = torch.randn(8, 3)
    a1, c1, oa1, oc1 = _pair(0)
    a2, c2, oa2, oc2 = _pair(0)
    la, lc = _losses(a1, c1, x)
    norms_sep = [oa1(la), oc1(lc)]
    la, lc = _losses(a2, c2, x)
    norms_joint = joint_step([(oa2, la), (oc2, lc)])
    assert norms_joint == pytest.approx(norms_sep, rel=1e-6)
    for m1, m2 in ((a1, a2), (c1, c2)):
        for p1, p2 in zip(m1.parameters(), m2.parameters()):
            torch.testing.assert_close(p1, p2)
    assert oa2.steps == oc2.steps == 1


def test_a_non_finite_loss_changes_nothing():
    actor, critic, oa, oc = _pair(1)
    before = [p.detach().clone() for p in (*actor.parameters(), *critic.parameters())]
    la, lc = _losses(actor, critic, torch.randn(4, 3))
    with pytest.raises(NonFiniteLoss):
        joint_step([(oa, la), (oc, lc * float("nan"))])
    after = [p.detach() for p in (*actor.parameters(), *critic.parameters())]
    assert all(torch.equal(b, a) for b, a in zip(before, after))
    assert oa.steps == oc.steps == 0
