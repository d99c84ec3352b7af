"""The one interface through which an algorithm plugs into the runtime.

The runtime (collectors, learner, reanalyzers, evaluator) only ever talks to these
classes; it never branches on an algorithm's name. An algorithm is a folder under
`wmdist/algos/` whose `Algorithm` subclass is registered in `wmdist/algos/registry.py`
(or named as `module:Class` in `algo.name`).

Step convention (observation-centric, one record per observation, as in DreamerV3):

    step t = obs_t            observation o_t                          [*obs_shape]
             reward_t         reward received on arriving at o_t (0 at first)
             first_t          o_t starts an episode
             last_t           o_t ends an episode (terminal or truncated)
             terminal_t       o_t is a true terminal state (no bootstrap beyond it)
             action_t         action taken at o_t (zeros at a last step)
             <extras>_t       what the Policy returned at o_t (zeros at a last step)

So MuZero's r_{t+1} is `reward[t+1]`, and a terminal episode stores its final
observation. Stored sequences are fixed-length windows of one episode; padding after the
episode's end has `mask = 0`.

Batches handed to `Learner.update` / `Reanalyzer.reanalyze` are dicts of numpy arrays
shaped `[B, T, ...]` (every stored field) plus `mask [B, T]` (1 where a real step is) and
`is_weight [B]` (importance weights, 1 for uniform sampling). Keys and stamps stay with
the runtime.

What an algorithm can do beyond that interface it declares as capabilities
(`Algorithm.capabilities`, the constants below); the runtime and the CLI ask
`algo.offers(CAPABILITY)` where they need one, never `algo.name`.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Mapping

import numpy as np

from wmdist.envs.spec import EnvSpec

if TYPE_CHECKING:
    from wmdist.envs.env import Env

Weights = dict[str, np.ndarray]  # a flat state dict as numpy arrays (cheap ray.put, no pickle)
Batch = dict[str, np.ndarray]  # field -> [B, T, ...], plus mask [B, T] and is_weight [B]

# Capabilities an Algorithm may declare in `capabilities` (a frozenset of these strings).
PREDICTS_OBSERVATIONS = "predicts_observations"  # decodes imagined observations: `dream_video` (`wmdist dream`)
TWO_PLAYER = "two_player"  # plays two-player games (acts for `to_play`, honours legal-action masks)
REANALYZE = "reanalyze"  # has a reanalyze step: `make_reanalyzer` returns a Reanalyzer
PLANS = "plans"  # searches or plans at decision time (e.g. MCTS), not only a policy network
# predicts embeddings, not observations (no decoder): `embedding_plot` (`wmdist dream` draws the planned
# embedding trajectory against the real one instead of a video)
PLOTS_EMBEDDINGS = "plots_embeddings"
# its learner restarts its state at `first` inside a sampled window, so one window may hold the end of
# an episode and the start of the next (`replay.pack_episodes`)
PACKED_WINDOWS = "packed_windows"
# trains a policy inside its model's dream: `dream_check` scores policies in the dream and the real env
# side by side (`wmdist dream RUN --check`)
CHECKS_DREAM = "checks_dream"
# its `world_model(weights)` is an RSSM `WorldModel` (wmdist/nets/world_model.py): `wmdist dream --error`
# measures how far ahead its open-loop predictions beat "no change"
MEASURES_PREDICTION = "measures_prediction"
CAPABILITIES: frozenset[str] = frozenset({PREDICTS_OBSERVATIONS, TWO_PLAYER, REANALYZE, PLANS, PLOTS_EMBEDDINGS,
                                          PACKED_WINDOWS, CHECKS_DREAM, MEASURES_PREDICTION})


@dataclass(frozen=True)
class FieldSpec:
    """One per-step field a sequence stores: its shape (without [T]) and numpy dtype name."""

    shape: tuple[int, ...]
    dtype: str


@dataclass
class UpdateResult:
    """What one learner update returns."""

    metrics: dict[str, float]  # scalar losses etc.; names become `wmdist_learner_<name>`
    priorities: np.ndarray | None = None  # [B] new priorities, or None to leave them
    extras: dict[str, float] = field(default_factory=dict)


class NonFiniteLoss(RuntimeError):
    """Raised by an update whose loss is NaN/inf, before any parameter changed."""


class Policy(ABC):
    """Acts for E environments at once (in a collector or the evaluator).

    Stateful: recurrent policies keep their per-env state and reset it where `first`.
    """

    @abstractmethod
    def set_weights(self, weights: Weights, version: int) -> None:
        """Load a weight snapshot published by the learner."""

    @abstractmethod
    def act(
        self,
        obs: np.ndarray,  # [E, *obs_shape]
        first: np.ndarray,  # [E] bool: o_t starts an episode (reset recurrent state)
        legal: np.ndarray | None,  # [E, A] bool legal-action mask (discrete envs), or None
        to_play: np.ndarray | None,  # [E] int player to move (two-player games), or None
        explore: bool,  # True in collectors, False for greedy evaluation
    ) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Return actions [E, ...] and per-step extras (each [E, ...]) to store."""

    def set_progress(self, env_steps: int, updates: int) -> None:
        """Told the run's progress (for temperature or exploration schedules)."""

    def taken(self, actions: np.ndarray) -> None:
        """Told the actions [E, ...] actually taken when they differ from the ones `act` returned
        (the collector's random warm-up): a recurrent policy conditions its next step on them."""


class Learner(ABC):
    """Owns the trainable parameters and optimizers (in the learner actor)."""

    @abstractmethod
    def update(self, batch: Batch) -> UpdateResult:
        """One gradient step; raise NonFiniteLoss (without stepping) if the loss is not finite."""

    @abstractmethod
    def get_weights(self) -> Weights:
        """The parameters collectors and reanalyzers need, as numpy arrays."""

    def get_eval_weights(self) -> Weights | None:
        """Other parameters for the evaluator and checkpoints (e.g. an average of the weights
        that only they act on), or None: they get `get_weights`."""
        return None

    @abstractmethod
    def state_dict(self) -> dict[str, Any]:
        """Everything to resume exactly: parameters, optimizer state, counters."""

    @abstractmethod
    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore what `state_dict` returned."""

    def use_services(self, services: Mapping[str, list]) -> None:
        """Handed, once at start, the actors of the algorithm's roles that serve the learner
        (`Role.serves_learner`, e.g. an evaluation pool) by role name; call them through
        `wmdist.runtime.calls`. Ignored by default."""


class Reanalyzer(ABC):
    """Refreshes stored targets with newer weights (MuZero Reanalyze, EfficientZero)."""

    @abstractmethod
    def set_weights(self, weights: Weights, version: int) -> None:
        """Load a weight snapshot published by the learner."""

    @abstractmethod
    def reanalyze(self, batch: Batch) -> dict[str, np.ndarray]:
        """Return fresh per-step fields ([B, T, ...]) to write back over the stored ones."""


class Algorithm(ABC):
    """Factory for an algorithm's parts; built in every process from (spec, config).

    Subclasses set `name` and `Config` (a dataclass of hyperparameters declared with
    `wmdist.config.fields.param`; it is the `algo` section of the run config), and
    `capabilities`: which of `CAPABILITIES` they offer (none by default).
    """

    name: ClassVar[str]
    Config: ClassVar[type]
    capabilities: ClassVar[frozenset[str]] = frozenset()

    @classmethod
    def offers(cls, capability: str) -> bool:
        """Whether this algorithm declares `capability` (one of `CAPABILITIES`)."""
        if capability not in CAPABILITIES:
            raise ValueError(f"unknown capability {capability!r}; known: {', '.join(sorted(CAPABILITIES))}")
        return capability in cls.capabilities

    @classmethod
    def extra_roles(cls, run_config: Any) -> list:
        """Roles this algorithm adds to the run (`wmdist.runtime.table.Role` entries: an
        evaluation pool, for example); none by default. Each is built, placed, scheduled,
        restarted and reported like the built-in ones."""
        return []

    def __init__(self, spec: EnvSpec, config: Any, seed: int = 0) -> None:
        self.spec = spec
        self.config = config
        self.seed = seed

    def validate(self) -> None:
        """Raise ValueError (one line) if this algorithm can't run on `self.spec`."""

    def check_run(self, run: Any) -> None:
        """Raise ValueError (one line) if the run's other sections (a `RunConfig`) cannot serve
        this algorithm's config, e.g. it needs reanalyzers and `reanalyze.num` is 0. Called
        before anything starts."""

    def host_memory(self) -> tuple[int, str]:
        """(bytes, what): memory the learner allocates outside torch as it is built, named by the
        config fields that size it. The model-size check refuses it before building (it cannot be
        measured on torch's meta device). (0, "") for none."""
        return 0, ""

    @abstractmethod
    def extra_fields(self) -> dict[str, FieldSpec]:
        """Per-step fields beyond obs/action/reward/first/last/terminal that replay stores
        (the extras `Policy.act` returns)."""

    @abstractmethod
    def make_policy(self, device: str = "cpu") -> Policy:
        ...

    @abstractmethod
    def make_learner(self, device: str = "cpu") -> Learner:
        ...

    def make_reanalyzer(self, device: str = "cpu") -> Reanalyzer | None:
        """None if the algorithm has no reanalyze step."""
        return None

    def dream_video(self, weights: Weights, env: Env, path: str, context: int = 5, horizon: int = 45) -> str:
        """Write a GIF of the world model's open-loop prediction beside the real observations
        (`context` filtered steps, then `horizon` imagined ones) to `path` and return the path.
        Only for algorithms that offer PREDICTS_OBSERVATIONS."""
        raise NotImplementedError(f"{type(self).__name__} does not predict observations")

    def embedding_plot(self, weights: Weights, env: Env, path: str, steps: int = 30) -> str:
        """Write a PNG of one planned episode's predicted embedding trajectory against the real
        one to `path` and return the path. Only for algorithms that offer PLOTS_EMBEDDINGS."""
        raise NotImplementedError(f"{type(self).__name__} does not plot embeddings")

    def dream_check(self, run_config: Any, weights: Weights, learner_state: Mapping[str, Any], rollouts: int,
                    episodes: int) -> list[dict[str, float | str]]:
        """Rows {policy, dream, real}: policies scored in the model's dream and in the real env.
        Only for algorithms that offer CHECKS_DREAM."""
        raise NotImplementedError(f"{type(self).__name__} does not train in a dream")

    def step_fields(self) -> dict[str, FieldSpec]:
        """Every per-step field of a stored sequence."""
        s = self.spec
        fields = {
            "obs": FieldSpec(tuple(s.obs_shape), s.obs_dtype),
            "action": FieldSpec(tuple(s.action_shape), s.action_dtype.name),
            "reward": FieldSpec((), "float32"),
            "first": FieldSpec((), "bool"),
            "last": FieldSpec((), "bool"),
            "terminal": FieldSpec((), "bool"),
        }
        fields.update(self.extra_fields())
        return fields
