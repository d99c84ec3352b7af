"""PlaNet configuration (defaults: the authors' numbers, docs/reference.md)."""
from __future__ import annotations

from dataclasses import dataclass

from wmdist.config.fields import MAX_LAYERS, param, section
from wmdist.nets.world_model import WorldModelSettings
from wmdist.search.cem import CEMConfig

# PlaNet's action repeat per dm_control domain (docs/reference.md); a preset sets `env.action_repeat`
# from it (the algorithm sees the env's spec, not its config).
ACTION_REPEAT: dict[str, int] = {"cartpole": 8, "cheetah": 4, "walker": 2, "finger": 2}


@dataclass
class PlaNetConfig:
    """The `algo` section for PlaNet: a Gaussian RSSM and a CEM planner, no policy network."""

    # --- world model -----------------------------------------------------------------
    deter: int = param(200, "GRU (deterministic state) width (PlaNet: 200)", ge=1)
    stoch: int = param(30, "Gaussian stochastic state size (PlaNet: 30)", ge=1)
    units: int = param(200, "hidden width of every MLP (PlaNet: 200)", ge=1)
    mlp_layers: int = param(2, "hidden layers of the vector encoder, the decoder and the reward head (PlaNet: 2)", ge=1,
                            le=MAX_LAYERS)
    cnn_depth: int = param(32, "channels of the first conv layer, 64x64 images (PlaNet: 32, a 1024-wide embedding)", ge=1)
    act: str = param("relu", "activation (PlaNet: ReLU)", choices=("elu", "silu", "relu", "tanh"))
    free_nats: float = param(3.0, "the batch-mean KL is clipped below at this many nats (PlaNet: 3)", ge=0)
    kl_scale: float = param(1.0, "weight of the one-step KL", ge=0)
    overshooting_distance: int = param(
        0, "latent overshooting: also match priors predicted up to this many steps ahead (0 = off; paper: 50)", ge=0)
    overshooting_scale: float = param(
        1.0, "latent overshooting: weight beta of the mean multi-step KL (the released code: 0)", ge=0)
    recon_scale: float = param(1.0, "decoder loss scale, 1 / the decoder's variance (PlaNet: 1, on 12,288 pixel "
                                    "values; a 5-d state needs ~100 for the model to encode what planning needs)", ge=0)
    reward_scale: float = param(1.0, "reward loss scale", ge=0)
    # --- optimisation ----------------------------------------------------------------
    model_lr: float = param(1e-3, "Adam learning rate (PlaNet: 1e-3)", gt=0)
    adam_eps: float = param(1e-4, "Adam epsilon (PlaNet: 1e-4)", gt=0)
    model_clip: float = param(1000.0, "gradient norm clip (PlaNet: 1000)", ge=0)
    # the update is one world-model phase; bf16 pays only where matmuls are native (AVX-512 BF16 / AMX, CUDA):
    # 1.26-1.41x faster at the preset's sizes on an AVX-512 BF16 EPYC (`wmdist bench planner`, learner_precision)
    precision: str = param("fp32", "learner precision: fp32, bf16, or auto (the first updates timed in each, the "
                                   "faster kept; fp32 without native bf16)", choices=("fp32", "bf16", "auto"))
    precision_trials: int = param(2, "auto: timed updates per precision after one warm-up update in each", ge=1)
    # --- acting ----------------------------------------------------------------------
    planner: CEMConfig = section(CEMConfig, "CEM planner run at every decision (PlaNet: H 12, J 1000, K 100, I 10)")
    expl_noise: float = param(0.3, "std of the Gaussian noise added to the planned action while collecting (PlaNet: 0.3)", ge=0)

    def validate(self) -> None:
        """One-line ValueError for combinations the ranges alone can't catch."""
        try:
            self.planner.validate()
        except ValueError as err:
            raise ValueError(str(err).replace("planner.", "algo.planner.")) from None  # name the full keys
        if self.overshooting_distance == 1:
            raise ValueError("algo.overshooting_distance must be 0 (off) or at least 2 (1 is the one-step KL)")

    def world_model(self) -> WorldModelSettings:
        """The shared world model's settings: a Gaussian latent, unit-Gaussian reward, no continue head."""
        return WorldModelSettings(
            deter=self.deter, stoch=self.stoch, classes=0, units=self.units, act=self.act,
            mlp_layers=self.mlp_layers, cnn_depth=self.cnn_depth,
        )
