"""Environments: one string id -> an `Env`; `VectorEnv` steps E of them in one process."""
from wmdist.envs.config import EnvConfig
from wmdist.envs.env import Env
from wmdist.envs.factory import check_id, env_spec, list_families, make_env
from wmdist.envs.spec import EnvSpec
from wmdist.envs.vector import VecStep, VectorEnv, make_vector_env

__all__ = [
    "Env", "EnvConfig", "EnvSpec", "VecStep", "VectorEnv",
    "check_id", "env_spec", "list_families", "make_env", "make_vector_env",
]
