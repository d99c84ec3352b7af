"""Dreamer V1/V2/V3 as one `Algorithm` (the version is configuration)."""
from __future__ import annotations

from wmdist.algos.base import MEASURES_PREDICTION, PACKED_WINDOWS, PREDICTS_OBSERVATIONS, Algorithm, FieldSpec, Weights
from wmdist.algos.dreamer.config import DreamerConfig
from wmdist.algos.dreamer.learner import DreamerLearner
from wmdist.algos.dreamer.policy import DreamerPolicy
from wmdist.envs.env import Env
from wmdist.envs.spec import EnvSpec
from wmdist.nets.world_model import WorldModel, check_spec, load_world_model


class Dreamer(Algorithm):
    name = "dreamer"
    Config = DreamerConfig
    # the decoder turns imagined latents into observations; the RSSM restarts at `first` inside a window
    capabilities = frozenset({PREDICTS_OBSERVATIONS, PACKED_WINDOWS, MEASURES_PREDICTION})

    def __init__(self, spec: EnvSpec, config: DreamerConfig | None = None, seed: int = 0) -> None:
        super().__init__(spec, config if config is not None else DreamerConfig(), seed)
        self.cfg = self.config.resolved()  # None fields filled from the version's defaults
        self.validate()

    def validate(self) -> None:
        check_spec(self.spec, "Dreamer")

    def extra_fields(self) -> dict[str, FieldSpec]:
        return {}  # the RSSM state is recomputed from the sequence; nothing extra is stored

    def make_policy(self, device: str = "cpu") -> DreamerPolicy:
        return DreamerPolicy(self.cfg, self.spec, device, self.seed)

    def make_learner(self, device: str = "cpu") -> DreamerLearner:
        return DreamerLearner(self.cfg, self.spec, device, self.seed)

    def world_model(self, weights: Weights) -> WorldModel:
        """The world model loaded from a weight snapshot (for the open-loop video)."""
        return load_world_model(WorldModel(self.cfg, self.spec), weights)

    def dream_video(self, weights: Weights, env: Env, path: str, context: int = 5, horizon: int = 45) -> str:
        from wmdist.algos.dream_video import open_loop_video  # imageio only when a video is made

        return open_loop_video(self, weights, env, path, context=context, horizon=horizon)
