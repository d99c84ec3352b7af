"""EfficientZero (Ye et al., 2021) behind the wmdist Algorithm interface, as MuZero plus three
additions; each can be switched off in the config (all off: MuZero Reanalyze)."""
from __future__ import annotations

from typing import Any

from wmdist.algos.base import FieldSpec
from wmdist.algos.efficientzero.build import build_net
from wmdist.algos.efficientzero.config import EfficientZeroConfig
from wmdist.algos.efficientzero.learner import EfficientZeroLearner
from wmdist.algos.efficientzero.policy import EfficientZeroPolicy
from wmdist.algos.efficientzero.reanalyzer import EfficientZeroReanalyzer
from wmdist.algos.muzero.algorithm import MuZero


class EfficientZero(MuZero):
    """Stored extras: MuZero's, plus `value_target []` float32 and `value_target_set []` bool
    (written by the reanalyzers) when the off-policy correction is on."""

    name = "efficientzero"
    Config = EfficientZeroConfig
    policy_cls, learner_cls, reanalyzer_cls = EfficientZeroPolicy, EfficientZeroLearner, EfficientZeroReanalyzer
    build = staticmethod(build_net)

    def __init__(self, spec, config: EfficientZeroConfig | None = None, seed: int = 0) -> None:
        super().__init__(spec, config if config is not None else EfficientZeroConfig(), seed)

    def validate(self) -> None:
        super().validate()
        if self.spec.players == 2 and self.config.value_prefix:
            # the movers' rewards alternate in sign, so a sum of them since a reset means nothing
            raise ValueError(f"algo.value_prefix is for one-player envs; {self.spec.id} has two players "
                             f"(set algo.value_prefix: false)")

    def check_run(self, run: Any) -> None:
        super().check_run(run)
        self.config.check_run(run)

    def extra_fields(self) -> dict[str, FieldSpec]:
        fields = super().extra_fields()
        if self.config.off_policy_correction:
            fields["value_target"] = FieldSpec((), "float32")
            fields["value_target_set"] = FieldSpec((), "bool")
        return fields
