"""C against a plain loop, on [z, h] (paper) and on z alone (`controller_h: false`)."""
import numpy as np
import pytest
import torch

from wmdist.algos.worldmodels.controller import act_batched, num_params
from wmdist.envs.spec import EnvSpec

CAR = EnvSpec(id="c", obs_shape=(64, 64, 3), obs_dtype="uint8", obs_kind="image", action_shape=(3,),
              action_low=(-1.0, 0.0, 0.0), action_high=(1.0, 1.0, 1.0))
DOOM = EnvSpec(id="d", obs_shape=(64, 64, 3), obs_dtype="uint8", obs_kind="image", num_actions=3)


def _loop(x: np.ndarray, z: np.ndarray, h: np.ndarray | None, spec: EnvSpec) -> np.ndarray:
    """One candidate, one step: a = W f + b with f = z or [z, h], W row-major then b."""
    f = z if h is None else np.concatenate([z, h])
    a = spec.action_dim
    out = np.array([sum(x[i * len(f) + j] * f[j] for j in range(len(f))) + x[a * len(f) + i] for i in range(a)])
    return int(out.argmax()) if spec.discrete else np.tanh(out)


def test_the_papers_counts():
    assert num_params(CAR, 32, 256) == 867  # paper, CarRacing
    assert num_params(CAR, 32, 256, reads_h=False) == 99  # paper's "V model only"


@pytest.mark.parametrize("spec", [CAR, DOOM])
@pytest.mark.parametrize("reads_h", [True, False])
def test_batched_controller_equals_a_plain_loop(spec, reads_h):
    rng = np.random.default_rng(1)
    n, r, zd, hd = 3, 4, 5, 7
    params = rng.normal(size=(n, num_params(spec, zd, hd, reads_h))).astype(np.float32)  # [N, P]
    z, h = rng.normal(size=(n, r, zd)).astype(np.float32), rng.normal(size=(n, r, hd)).astype(np.float32)
    got = act_batched(torch.as_tensor(params), torch.as_tensor(z), torch.as_tensor(h), spec).numpy()
    for i in range(n):
        for j in range(r):
            want = _loop(params[i].astype(np.float64), z[i, j], h[i, j] if reads_h else None, spec)
            np.testing.assert_allclose(got[i, j], want, atol=1e-5)


def test_a_controller_of_another_size_is_refused():
    with pytest.raises(ValueError, match="does not read z"):
        act_batched(torch.zeros(1, 30), torch.zeros(1, 1, 5), torch.zeros(1, 1, 7), CAR)
