"""EfficientZeroConfig: MuZero's `algo` section plus EfficientZero's three additions.

Each addition has a switch (`value_prefix`, `consistency_weight`, `off_policy_correction`):
with all three off this is MuZero Reanalyze, so ablations are config changes. Defaults are
the authors' numbers (docs/reference.md, EfficientZero) unless a field says otherwise.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from wmdist.algos.muzero.config import MuZeroConfig
from wmdist.config.fields import MAX_LAYERS, param


@dataclass
class EfficientZeroConfig(MuZeroConfig):
    # MuZero fields whose EfficientZero defaults differ (docs/reference.md, EfficientZero)
    td_steps: int = param(5, "n of the n-step value target, before the off-policy correction (authors: 5)", ge=1)
    value_loss_weight: float = param(0.25, "weight of the value loss (authors: 0.25)", ge=0)
    conv_channels: int = param(64, "conv: channels of the residual towers (authors' Atari network: 64)", ge=2)
    conv_blocks: int = param(1, "conv: residual blocks in each of h, g, f (authors: 1)", ge=0, le=MAX_LAYERS)
    conv_head_channels: int = param(16, "conv: channels of the 1x1 conv before each head (authors: 16)", ge=1)
    conv_downsample_blocks: list[int] = param(
        [1, 1, 1], "conv, atari stem: residual blocks in the three stages of the 96 -> 6 downsampling "
                   "(authors: 1, 1, 1; MuZero: 2, 3, 3)", ge=0)

    # value prefix (the search's lstm_horizon is the reset period in training too)
    value_prefix: bool = param(True, "predict the value prefix (reward sum since the last LSTM reset) with an LSTM "
                                     "instead of per-step rewards; false = MuZero's reward head")
    lstm_hidden: int = param(512, "value-prefix LSTM hidden size (authors: 512)", ge=1)

    # self-supervised temporal consistency
    consistency_weight: float = param(2.0, "weight of the consistency loss (authors: 2; 0 = off)", ge=0)
    proj_hidden: int = param(1024, "consistency projector hidden width (authors: 1024)", ge=1)
    proj_dim: int = param(1024, "consistency projection width (authors: 1024)", ge=1)
    pred_hidden: int = param(512, "consistency predictor hidden width (authors: 512)", ge=1)

    # off-policy correction, in the reanalyzers
    off_policy_correction: bool = param(
        True, "reanalyzers write value targets whose horizon shrinks with the data's age: "
              "l = clip(n - floor(age / tau), 1, n) (needs reanalyze.num > 0)")
    off_policy_tau_ratio: float = param(0.3, "tau = ratio x off_policy_training_steps (authors: 0.3)", gt=0)
    off_policy_training_steps: int = param(
        100_000, "the run's total training steps that tau scales (authors: 100k, so tau = 30k transitions)", ge=1)
    off_policy_bootstrap: str = param(
        "net", "value at t + l: the network's ('net': the reanalyzer's weights, the learner's latest published "
               "ones, i.e. a target network refreshed at each publication, as the authors run it) or a fresh "
               "noise-free root search's ('search')", choices=("net", "search"))
    reanalyze_policy_fraction: float = param(
        0.99, "share of reanalyzed sequences whose policy targets a fresh search refreshes (authors: 0.99)", ge=0, le=1)

    @property
    def off_policy_tau(self) -> float:
        """tau in transitions of age per step of horizon lost."""
        return self.off_policy_tau_ratio * self.off_policy_training_steps

    def has_value_prefix_net(self) -> bool:
        return self.value_prefix

    def validate(self) -> "EfficientZeroConfig":
        if self.value_prefix:
            self.search.value_prefix = True  # the search reads the same head
        super().validate()
        if self.consistency_weight > 0 and self.augment_symmetries:
            raise ValueError("algo.consistency_weight > 0 cannot be combined with algo.augment_symmetries "
                             "(the consistency target would need the same symmetry)")
        return self

    def check_run(self, run: Any) -> None:
        """Cross-section check: the correction is computed by reanalyzers."""
        if self.off_policy_correction and run.reanalyze.num < 1:
            raise ValueError("algo.off_policy_correction needs reanalyzers (set reanalyze.num >= 1, "
                             "or algo.off_policy_correction: false)")
