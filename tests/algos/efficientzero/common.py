"""Small EfficientZero configs and a vector-observation spec for the tests."""
from __future__ import annotations

from wmdist.algos.efficientzero import EfficientZero, EfficientZeroConfig
from wmdist.envs.spec import EnvSpec
from wmdist.nets.optim import OptimConfig
from wmdist.search.api import SearchConfig

SPEC = EnvSpec(id="test:vec", obs_shape=(3,), obs_dtype="float32", obs_kind="vector", num_actions=3)


def small_config(**kw) -> EfficientZeroConfig:
    search = kw.pop("search", SearchConfig(num_simulations=6))
    base = dict(optim=OptimConfig(kind="adam", lr=1e-2), latent_dim=8, hidden=[16], value_support=5,
                reward_support=3, td_steps=3, lstm_hidden=8, proj_hidden=8, proj_dim=8, pred_hidden=4)
    base.update(kw)
    return EfficientZeroConfig(search=search, **base).validate()


def small_algo(spec: EnvSpec = SPEC, **kw) -> EfficientZero:
    return EfficientZero(spec, small_config(**kw), seed=0)
