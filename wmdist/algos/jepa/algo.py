"""JEPA with SIGReg (LeWorldModel, Maes et al. 2026) as an `Algorithm`: a reconstruction-free
world model trained on reward-free exploration data that plans with CEM to a goal image."""
from __future__ import annotations

from typing import Any

from wmdist.algos.base import PLANS, PLOTS_EMBEDDINGS, Algorithm, FieldSpec, Weights
from wmdist.algos.jepa.config import JepaConfig
from wmdist.algos.jepa.learner import JepaLearner
from wmdist.algos.jepa.policy import OBS_SHAPE, JepaPolicy
from wmdist.envs.env import Env
from wmdist.envs.spec import EnvSpec


class Jepa(Algorithm):
    name = "jepa"
    Config = JepaConfig
    # every evaluation action is planned with CEM; there is no decoder, so no PREDICTS_OBSERVATIONS
    capabilities = frozenset({PLANS, PLOTS_EMBEDDINGS})

    def __init__(self, spec: EnvSpec, config: JepaConfig | None = None, seed: int = 0) -> None:
        super().__init__(spec, config if config is not None else JepaConfig(), seed)
        self.cfg = self.config
        self.cfg.validate()
        self.validate()

    def validate(self) -> None:
        s = self.spec
        if tuple(s.obs_shape) != OBS_SHAPE or s.obs_dtype != "uint8":
            raise ValueError(f"JEPA plans to a goal image: it needs uint8 observations {list(OBS_SHAPE)} (a 64x64 frame "
                             f"and the goal image, e.g. nav:tworooms), {s.id} gives {s.obs_dtype} {list(s.obs_shape)}")
        if s.discrete:
            raise ValueError(f"JEPA's CEM planner needs continuous actions, {s.id} has {s.num_actions} discrete actions")

    def check_run(self, run: Any) -> None:
        # The evaluator plans, and planning before any update is an error: evaluations must come
        # after training has started, so only by env steps, beyond the steps replay waits for.
        if run.eval.enabled:
            if run.eval.every_seconds > 0:
                raise ValueError("jepa: set eval.every_seconds: 0 and evaluate by eval.every_env_steps "
                                 "(an evaluation before the first update would plan with an untrained model)")
            if run.eval.every_env_steps <= run.replay.min_size:
                raise ValueError(f"jepa: eval.every_env_steps ({run.eval.every_env_steps}) must exceed replay.min_size "
                                 f"({run.replay.min_size}) so that training has started by the first evaluation")
        if run.replay.seq_len <= self.cfg.history:
            raise ValueError(f"jepa: replay.seq_len ({run.replay.seq_len}) must exceed algo.history "
                             f"({self.cfg.history}): each window needs a next step to predict")
        if self.cfg.rollout_steps > 1 and run.replay.seq_len < self.cfg.history + self.cfg.rollout_steps:
            raise ValueError(f"jepa: algo.rollout_steps {self.cfg.rollout_steps} needs replay.seq_len >= algo.history + "
                             f"rollout_steps = {self.cfg.history + self.cfg.rollout_steps}, got {run.replay.seq_len}")

    def extra_fields(self) -> dict[str, FieldSpec]:
        return {}  # embeddings are recomputed from the frames

    def make_policy(self, device: str = "cpu") -> JepaPolicy:
        return JepaPolicy(self.cfg, self.spec, device, self.seed)

    def make_learner(self, device: str = "cpu") -> JepaLearner:
        return JepaLearner(self.cfg, self.spec, device, self.seed)

    def embedding_plot(self, weights: Weights, env: Env, path: str, steps: int = 30) -> str:
        """Write a PNG of one planned episode in embedding space (no decoder: the plot stands in
        for `wmdist dream`'s video): the real embeddings, each decision's predicted trajectory
        and the goal's, projected on their first two principal components."""
        from wmdist.algos.jepa.trajectory_plot import plot_planned_episode  # matplotlib only when plotting

        return plot_planned_episode(self, weights, env, path, steps)
