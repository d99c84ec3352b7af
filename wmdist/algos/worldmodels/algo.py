"""World Models (Ha & Schmidhuber 2018) as an `Algorithm`: V, M, and C by CMA-ES, with an
evaluation pool (role `wm_eval`) that scores the candidates in parallel."""
from __future__ import annotations

from typing import Any, Mapping

from wmdist.algos.base import CHECKS_DREAM, PREDICTS_OBSERVATIONS, Algorithm, FieldSpec, Weights
from wmdist.algos.worldmodels.config import WorldModelsConfig
from wmdist.algos.worldmodels.learner import POOL_ROLE, WorldModelsLearner
from wmdist.algos.worldmodels.policy import WorldModelsPolicy
from wmdist.envs.env import Env
from wmdist.envs.spec import EnvSpec


def _worker_cls() -> type:
    from wmdist.algos.worldmodels.worker import EvalWorker

    return EvalWorker


class WorldModels(Algorithm):
    name = "worldmodels"
    Config = WorldModelsConfig
    capabilities = frozenset({PREDICTS_OBSERVATIONS, CHECKS_DREAM})  # V decodes M's imagined latents; C trains in M's dream

    def __init__(self, spec: EnvSpec, config: WorldModelsConfig | None = None, seed: int = 0) -> None:
        super().__init__(spec, config if config is not None else WorldModelsConfig(), seed)
        self.cfg = self.config
        self.cfg.validate()
        self.validate()

    @classmethod
    def extra_roles(cls, run_config: Any) -> list:
        """The evaluation pool: `algo.eval_actors` actors the learner hands candidates to (built
        before the learner, which gets their handles; restarted by Ray when one dies)."""
        from wmdist.runtime.table import SERVICE, Role, RoleResources

        return [Role(POOL_ROLE, _worker_cls, lambda cfg: cfg.algo, lambda cfg: cfg.algo.eval_actors,
                     lambda sec: RoleResources(sec.eval_actor_cpus, custom=dict(sec.eval_actor_resources)),
                     args=lambda ctx, i, res: (ctx.cfg, ctx.spec, i, res.threads),
                     schedule=SERVICE, serves_learner=True)]

    def validate(self) -> None:
        s = self.spec
        if s.obs_kind != "image" or len(s.obs_shape) != 3 or tuple(s.obs_shape[:2]) != (64, 64):
            raise ValueError(f"World Models' VAE needs 64x64 image observations, {s.id} gives {s.obs_shape}")

    def host_memory(self) -> tuple[int, str]:
        """CMA-ES's full covariance over the controller (`algo.z_dim=1e8` spent a minute allocating it)."""
        from wmdist.algos.worldmodels.cmaes import covariance_bytes
        from wmdist.algos.worldmodels.controller import num_params

        n = num_params(self.spec, self.cfg.z_dim, self.cfg.rnn_hidden, self.cfg.controller_h)
        return covariance_bytes(n), (f"algo.z_dim / algo.rnn_hidden: CMA-ES's full covariance over the "
                                     f"controller's {n:,} parameters")

    def extra_fields(self) -> dict[str, FieldSpec]:
        return {}

    def make_policy(self, device: str = "cpu") -> WorldModelsPolicy:
        return WorldModelsPolicy(self.cfg, self.spec, device, self.seed)

    def make_learner(self, device: str = "cpu") -> WorldModelsLearner:
        return WorldModelsLearner(self.cfg, self.spec, device, self.seed)

    def dream_video(self, weights: Weights, env: Env, path: str, context: int = 5, horizon: int = 45) -> str:
        from wmdist.algos.worldmodels.dream import world_models_video

        return world_models_video(self, weights, env, path, context, horizon)

    def dream_check(self, run_config: Any, weights: Weights, learner_state: Mapping[str, Any], rollouts: int,
                    episodes: int) -> list[dict[str, float | str]]:
        from wmdist.algos.worldmodels.dream_check import dream_check

        return dream_check(run_config, self.spec, weights, learner_state, rollouts, episodes, seed=run_config.run.seed)
