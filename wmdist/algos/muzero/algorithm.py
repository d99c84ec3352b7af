"""MuZero (Schrittwieser et al., 2020) and MuZero Reanalyze behind the wmdist Algorithm interface."""
from __future__ import annotations

from wmdist.algos.base import PLANS, REANALYZE, TWO_PLAYER, Algorithm, FieldSpec
from wmdist.algos.muzero.build import build_net, check_spec
from wmdist.algos.muzero.config import MuZeroConfig
from wmdist.algos.muzero.learner import MuZeroLearner
from wmdist.algos.muzero.policy import MuZeroPolicy
from wmdist.algos.muzero.reanalyzer import MuZeroReanalyzer


class MuZero(Algorithm):
    """Stored extras per step: `search_policy [A]`, `search_value []`; two-player games also
    store `legal [A] bool` and `to_play [] int8` (the reanalyzer searches with them)."""

    name = "muzero"
    Config = MuZeroConfig
    # acts by MCTS; Reanalyze reruns that search on stored data; board games search for `to_play`
    capabilities = frozenset({PLANS, REANALYZE, TWO_PLAYER})
    # the parts a subclass (EfficientZero) swaps for its own
    policy_cls, learner_cls, reanalyzer_cls = MuZeroPolicy, MuZeroLearner, MuZeroReanalyzer
    build = staticmethod(build_net)

    def __init__(self, spec, config: MuZeroConfig | None = None, seed: int = 0) -> None:
        super().__init__(spec, config if config is not None else MuZeroConfig(), seed)
        self.config.validate()

    def validate(self) -> None:
        check_spec(self.spec, self.config)

    def check_run(self, run) -> None:
        # a sample unrolls K steps inside its stored window: with K >= seq_len no sample has its
        # whole unroll in the data, and every step past the window trains on nothing
        if self.config.unroll_steps >= run.replay.seq_len:
            raise ValueError(f"algo.unroll_steps ({self.config.unroll_steps}) must be below replay.seq_len "
                             f"({run.replay.seq_len}): each sample unrolls that many steps inside its window")

    def extra_fields(self) -> dict[str, FieldSpec]:
        a = self.spec.num_actions
        fields = {"search_policy": FieldSpec((a,), "float32"), "search_value": FieldSpec((), "float32")}
        if self.spec.players == 2:
            fields["legal"] = FieldSpec((a,), "bool")
            fields["to_play"] = FieldSpec((), "int8")
        return fields

    def _net(self):
        import torch

        torch.manual_seed(self.seed)  # every process builds the same initial weights
        return self.build(self.spec, self.config)

    def make_policy(self, device: str = "cpu") -> MuZeroPolicy:
        return self.policy_cls(self._net(), self.config, self.spec, self.seed + 1, device)

    def make_learner(self, device: str = "cpu") -> MuZeroLearner:
        return self.learner_cls(self._net(), self.config, self.spec.num_actions, self.spec.players, self.seed + 2,
                                device, symmetries=self.spec.symmetries)

    def make_reanalyzer(self, device: str = "cpu") -> MuZeroReanalyzer:
        return self.reanalyzer_cls(self._net(), self.config, self.spec, self.seed + 3, device)
