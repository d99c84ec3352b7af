"""PlaNet (Hafner et al. 2019) as an `Algorithm`: an RSSM world model and CEM planning."""
from __future__ import annotations

from wmdist.algos.base import MEASURES_PREDICTION, PLANS, PREDICTS_OBSERVATIONS, Algorithm, FieldSpec, Weights
from wmdist.algos.planet.config import PlaNetConfig
from wmdist.algos.planet.learner import PlaNetLearner
from wmdist.algos.planet.policy import PlaNetPolicy
from wmdist.envs.env import Env
from wmdist.envs.spec import EnvSpec
from wmdist.nets.world_model import WorldModel, check_spec, load_world_model


class PlaNet(Algorithm):
    name = "planet"
    Config = PlaNetConfig
    # the decoder turns imagined latents into observations; every action is planned with CEM
    capabilities = frozenset({PREDICTS_OBSERVATIONS, PLANS, MEASURES_PREDICTION})

    def __init__(self, spec: EnvSpec, config: PlaNetConfig | None = None, seed: int = 0) -> None:
        super().__init__(spec, config if config is not None else PlaNetConfig(), seed)
        self.cfg = self.config
        self.cfg.validate()
        self.validate()

    def validate(self) -> None:
        s = self.spec
        if s.discrete:
            raise ValueError(f"PlaNet's CEM planner needs continuous actions, {s.id} has {s.num_actions} discrete actions")
        check_spec(s, "PlaNet")

    def extra_fields(self) -> dict[str, FieldSpec]:
        return {}  # the RSSM state is recomputed from the sequence

    def make_policy(self, device: str = "cpu") -> PlaNetPolicy:
        return PlaNetPolicy(self.cfg, self.spec, device, self.seed)

    def make_learner(self, device: str = "cpu") -> PlaNetLearner:
        return PlaNetLearner(self.cfg, self.spec, device, self.seed)

    def world_model(self, weights: Weights) -> WorldModel:
        """The world model loaded from a weight snapshot (for the open-loop video)."""
        return load_world_model(WorldModel(self.cfg.world_model(), self.spec), weights)

    def dream_video(self, weights: Weights, env: Env, path: str, context: int = 5, horizon: int = 45) -> str:
        from wmdist.algos.dream_video import open_loop_video  # imageio only when a video is made

        return open_loop_video(self, weights, env, path, context=context, horizon=horizon)
