"""Dreamer configuration: one `version` (1, 2, 3) whose paper numbers fill any field left at None.

A preset may set every field explicitly so it reads as the paper's table; a field left at
None takes `VERSION_DEFAULTS[version]` (docs/reference.md; V1/V2 DMC numbers, V3 arXiv v1).
`resolved()` returns the config with every None replaced.
"""
from __future__ import annotations

import dataclasses
import os
import shutil
from dataclasses import dataclass
from typing import Any

from wmdist.config.fields import MAX_HORIZON, MAX_LAYERS, param

# DreamerV3 (arXiv v1) model sizes: GRU units, MLP units, CNN depth, MLP layers.
V3_SIZES: dict[str, tuple[int, int, int, int]] = {
    "xs": (256, 256, 24, 1),
    "s": (512, 512, 32, 2),
    "m": (1024, 640, 48, 3),
    "l": (2048, 768, 64, 4),
    "xl": (4096, 1024, 96, 5),
}

VERSION_DEFAULTS: dict[int, dict[str, Any]] = {
    1: dict(  # Dreamer (Hafner et al. 2020), authors' code
        deter=200, units=300, mlp_layers=2, stoch=30, classes=0, cnn_depth=32, act="elu", norm=False,
        gru_norm=False, unimix=0.0, symlog_inputs=False, symlog_targets=False, reward_head="mse",
        critic_head="mse", cont_head=False, kl_dyn=1.0, kl_rep=1.0, free_nats=3.0, free_avg=True,
        discount=0.99, actor_grad_disc="backprop", actor_grad_cont="backprop", actor_entropy=0.0,
        actor_dist_cont="tanh_normal", expl_noise=0.3, return_norm="none", slow_critic="none",
        slow_critic_mix=1.0, slow_critic_every=1, model_lr=6e-4, actor_lr=8e-5, critic_lr=8e-5,
        model_clip=100.0, ac_clip=100.0, adam_eps=1e-7,
    ),
    2: dict(  # DreamerV2 (Hafner et al. 2021): 32x32 categoricals, KL balancing 0.8
        deter=200, units=400, mlp_layers=2, stoch=32, classes=32, cnn_depth=48, act="elu", norm=False,
        gru_norm=True, unimix=0.0, symlog_inputs=False, symlog_targets=False, reward_head="mse",
        critic_head="mse", cont_head=True, kl_dyn=0.8, kl_rep=0.2, free_nats=1.0, free_avg=True,
        discount=0.99, actor_grad_disc="reinforce", actor_grad_cont="backprop", actor_entropy=1e-4,
        actor_dist_cont="normal", expl_noise=0.0, return_norm="none", slow_critic="target",
        slow_critic_mix=1.0, slow_critic_every=100, model_lr=3e-4, actor_lr=8e-5, critic_lr=8e-5,
        model_clip=100.0, ac_clip=100.0, adam_eps=1e-5,
    ),
    3: dict(  # DreamerV3 (Hafner et al. 2023, arXiv v1), size S
        deter=512, units=512, mlp_layers=2, stoch=32, classes=32, cnn_depth=32, act="silu", norm=True,
        gru_norm=True, unimix=0.01, symlog_inputs=True, symlog_targets=True, reward_head="twohot",
        critic_head="twohot", cont_head=True, kl_dyn=0.5, kl_rep=0.1, free_nats=1.0, free_avg=False,
        discount=0.997, actor_grad_disc="reinforce", actor_grad_cont="backprop", actor_entropy=3e-4,
        actor_dist_cont="normal", expl_noise=0.0, return_norm="percentile", slow_critic="reg",
        slow_critic_mix=0.02, slow_critic_every=1, model_lr=1e-4, actor_lr=3e-5, critic_lr=3e-5,
        model_clip=1000.0, ac_clip=100.0, adam_eps=1e-8,
    ),
}


@dataclass
class DreamerConfig:
    """The `algo` section for Dreamer V1/V2/V3 (None = the version's paper default)."""

    version: int = param(3, "Dreamer version whose paper numbers fill fields left at None", choices=(1, 2, 3))
    size: str | None = param(None, "V3 model size preset (xs|s|m|l|xl) for deter/units/cnn_depth/mlp_layers", choices=tuple(V3_SIZES))
    # --- world model -----------------------------------------------------------------
    deter: int | None = param(None, "GRU (deterministic state) width", ge=1)
    units: int | None = param(None, "hidden width of every MLP", ge=1)
    mlp_layers: int | None = param(None, "hidden layers of encoder/decoder/heads/actor/critic MLPs", ge=1, le=MAX_LAYERS)
    stoch: int | None = param(None, "stochastic state: Gaussian size (classes=0) or number of categoricals", ge=1)
    classes: int | None = param(None, "classes per categorical latent (0 = Gaussian latent, V1)", ge=0)
    cnn_depth: int | None = param(None, "channels of the first conv layer (64x64 images)", ge=1)
    act: str | None = param(None, "activation", choices=("elu", "silu", "relu", "tanh"))
    norm: bool | None = param(None, "LayerNorm in every MLP/conv block (V3)")
    gru_norm: bool | None = param(None, "LayerNorm inside the GRU (V2, V3)")
    unimix: float | None = param(None, "uniform mix in every categorical (V3: 0.01)", ge=0, lt=1)
    symlog_inputs: bool | None = param(None, "symlog vector observations before the encoder (V3)")
    symlog_targets: bool | None = param(None, "vector decoder predicts symlog(obs) (V3)")
    reward_head: str | None = param(None, "reward head: unit Gaussian (mse) or two-hot symlog bins", choices=("mse", "twohot"))
    critic_head: str | None = param(None, "critic head: mse or two-hot symlog bins", choices=("mse", "twohot"))
    bins: int = param(255, "two-hot bins (V3: 255)", ge=2)
    bin_low: float = param(-20.0, "lowest two-hot bin (symlog space)")
    bin_high: float = param(20.0, "highest two-hot bin (symlog space)")
    cont_head: bool | None = param(None, "learn a continue (1 - terminal) head; off = fixed discount (V1)")
    kl_dyn: float | None = param(None, "dynamics KL scale, trains the prior (V2: 0.8 x kl scale; V3: 0.5)", ge=0)
    kl_rep: float | None = param(None, "representation KL scale, trains the posterior (V2: 0.2; V3: 0.1)", ge=0)
    free_nats: float | None = param(None, "KL terms are clipped below at this many nats (V1: 3, V3: 1)", ge=0)
    free_avg: bool | None = param(None, "apply free nats to the batch-mean KL (V1/V2) instead of per step (V3)")
    recon_scale: float = param(1.0, "decoder loss scale, 1 / the decoder's variance (papers: 1; the V1, V2 and V3 "
                                    "dm_control presets from a 5-d state and the V3 MinAtar ones: 100, so the model "
                                    "encodes the pole or the ball rather than pay its KL)", ge=0)
    reward_scale: float = param(1.0, "reward loss scale", ge=0)
    cont_scale: float = param(1.0, "continue loss scale", ge=0)
    cont_terminal_weight: float = param(1.0, "weight of a terminal step's continue loss against a non-terminal "
                                             "one's (papers: 1). Above 1 the rare ends in replay (a cart leaving the "
                                             "track, issue 24) teach the continue head more, and it calls states "
                                             "near such ends terminal sooner", ge=1)
    # --- behaviour -------------------------------------------------------------------
    horizon: int = param(15, "imagination horizon H", ge=1, le=MAX_HORIZON)
    imag_starts: int = param(0, "imagine from at most this many posterior states, drawn at random from the batch (0 = all, as the papers)", ge=0)
    discount: float | None = param(None, "discount gamma (V3: 1 - 1/333)", gt=0, le=1)
    lam: float = param(0.95, "lambda of the lambda-returns", ge=0, le=1)
    # not in the papers (one lambda for both): a lower one gives the actor an advantage with less of the
    # sampled future actions' variance in it, trusting the critic instead
    actor_lam: float | None = param(None, "lambda of the returns in the actor's advantage (None = lam; the "
                                    "critic always regresses lam-returns)", ge=0, le=1)
    actor_grad_disc: str | None = param(None, "actor gradient for discrete actions", choices=("reinforce", "backprop"))
    actor_grad_cont: str | None = param(None, "actor gradient for continuous actions", choices=("reinforce", "backprop"))
    actor_entropy: float | None = param(None, "actor entropy bonus (V3: 3e-4)", ge=0)
    actor_dist_cont: str | None = param(None, "continuous actor distribution", choices=("tanh_normal", "normal"))
    actor_min_std: float = param(0.1, "lowest std of the continuous actor", gt=0)
    actor_max_std: float = param(1.0, "highest std of the continuous actor (normal)", gt=0)
    actor_init_std: float = param(5.0, "std of the continuous actor at initialisation (tanh_normal; V1 authors' code: 5, "
                                  "which saturates the tanh for most samples)", gt=0)
    expl_noise: float | None = param(None, "Gaussian noise added to the actor's sample when exploring (V1: 0.3)", ge=0)
    greedy_fraction: float = param(0.0, "share of each collector's envs that act on the actor's mode instead of its "
                                         "sample, so replay holds the states the greedy policy reaches "
                                         "(wmdist/algos/greedy_share.py; not in the papers)", ge=0, le=1)
    return_norm: str | None = param(None, "advantage normalisation (V3: percentile P5-P95)", choices=("none", "percentile"))
    return_decay: float = param(0.99, "EMA decay of the return percentiles", ge=0, lt=1)
    return_low: float = param(0.05, "lower return percentile", ge=0, le=1)
    return_high: float = param(0.95, "upper return percentile", ge=0, le=1)
    slow_critic: str | None = param(None, "slow critic: none (V1), target for returns (V2), regulariser (V3)", choices=("none", "target", "reg"))
    slow_critic_mix: float | None = param(None, "slow critic update fraction (V2 1.0 every 100; V3 0.02 every update)", gt=0, le=1)
    slow_critic_every: int | None = param(None, "updates between slow-critic updates", ge=1)
    slow_reg_scale: float = param(1.0, "weight of the slow-critic regulariser (V3)", ge=0)
    repval_scale: float = param(0.0, "weight of the critic replay loss: lambda-returns over the replayed rewards and "
                                "terminations (revised DreamerV3: 0.3; 0 = off, as arXiv v1)", ge=0)
    # --- optimisation ----------------------------------------------------------------
    model_lr: float | None = param(None, "world-model Adam learning rate", gt=0)
    actor_lr: float | None = param(None, "actor Adam learning rate", gt=0)
    critic_lr: float | None = param(None, "critic Adam learning rate", gt=0)
    # not in the papers: lets late policy versions change less, where evaluations swing between
    # neighbouring versions (issue 24, BENCHMARKS); off by default
    actor_lr_decay_updates: int = param(0, "updates over which the actor's learning rate falls linearly to "
                                        "actor_lr x actor_lr_decay_to, then stays (0 = constant, as the papers)", ge=0)
    actor_lr_decay_to: float = param(1.0, "the factor the actor's learning rate reaches after actor_lr_decay_updates",
                                     gt=0, le=1)
    # not in the papers: the acting policy then changes smoothly between neighbouring versions (issue 24)
    publish_ema: float = param(0.0, "decay per update of an exponential moving average of the world model and "
                               "actor that collectors, the evaluator and checkpoints get (Polyak averaging); "
                               "0 publishes the learner's own weights", ge=0, lt=1)
    model_clip: float | None = param(None, "world-model gradient norm clip", ge=0)
    ac_clip: float | None = param(None, "actor and critic gradient norm clip", ge=0)
    adam_eps: float | None = param(None, "Adam epsilon", gt=0)
    # pays where bf16 matmuls are native (AVX-512 BF16 / AMX CPUs, CUDA) and the model is large
    # enough for matmuls to dominate: 1.47x on the 256-unit model, ~1.1x at 128 (BENCHMARKS)
    bf16: bool = param(False, "run the learner's forward passes under bfloat16 autocast (fp32 otherwise); "
                       "the default of both precision_* fields")
    # per phase: the world model and the actor-critic gain differently from bf16 (BENCHMARKS)
    precision_world_model: str | None = param(
        None, "world-model phase: fp32, bf16, or auto (the first updates timed in each, the faster kept; "
        "fp32 without native bf16); None follows `bf16`", choices=("fp32", "bf16", "auto"))
    precision_actor_critic: str | None = param(
        None, "imagination + actor-critic phase: fp32, bf16 or auto (as precision_world_model); None follows `bf16`",
        choices=("fp32", "bf16", "auto"))
    precision_trials: int = param(2, "auto: timed updates per precision after one warm-up update in each", ge=1)
    # One graph per phase fuses its elementwise work, forward and backward. On the small V3 model (2 threads,
    # Intel Xeon with AMX; BENCHMARKS, session 49), side by side with eager: the actor-critic alone 1.32x
    # (discrete) and 1.25x (continuous); with the world model too 1.51x and 1.37x (2.42 and 1.73 updates/s).
    compile_actor_critic: bool = param(
        False, "run imagination + the actor-critic losses through torch.compile (inductor); costs 2-3 minutes "
        "of compiling at start-up per precision the phase runs in, and needs a C++ compiler on CPU")
    compile_world_model: bool = param(
        False, "run the world model's losses (encoder, the T observe steps, heads, KL) through torch.compile; "
        "costs 4-8 minutes of compiling per precision on a first start (T = 64), far less from inductor's cache, "
        "and needs a C++ compiler on CPU")

    def resolved(self) -> "DreamerConfig":
        """A copy with every None replaced by the version's default (and the V3 size table)."""
        if self.version not in VERSION_DEFAULTS:
            raise ValueError(f"algo.version must be 1, 2 or 3, got {self.version!r}")
        values = dict(VERSION_DEFAULTS[self.version])
        if self.size is not None:
            if self.size not in V3_SIZES:
                raise ValueError(f"algo.size must be one of {sorted(V3_SIZES)}, got {self.size!r}")
            values.update(zip(("deter", "units", "cnn_depth", "mlp_layers"), V3_SIZES[self.size]))
        changes = {k: v for k, v in values.items() if getattr(self, k) is None}
        out = dataclasses.replace(self, **changes)
        out.validate()
        return out

    def validate(self) -> None:
        """One-line ValueError for combinations the ranges alone can't catch."""
        lo, hi = self.return_low, self.return_high
        if not lo < hi:
            raise ValueError(f"algo.return_low ({lo}) must be below algo.return_high ({hi})")
        if not self.bin_low < self.bin_high:
            raise ValueError(f"algo.bin_low ({self.bin_low}) must be below algo.bin_high ({self.bin_high})")
        if self.actor_min_std >= self.actor_max_std:
            raise ValueError("algo.actor_min_std must be below algo.actor_max_std")
        if self.classes == 1:
            raise ValueError("algo.classes must be 0 (Gaussian) or at least 2")
        for name in ("compile_world_model", "compile_actor_critic"):
            if getattr(self, name) and not cxx_compiler():
                raise ValueError(f"algo.{name} needs a C++ compiler for torch.compile (g++, clang++ "
                                 "or $CXX); install one (`make system-deps`) or set it false")


def cxx_compiler() -> str | None:
    """The C++ compiler inductor would build CPU kernels with ($CXX, else g++ or clang++), if any."""
    names = [os.environ["CXX"]] if os.environ.get("CXX") else ["g++", "clang++"]
    return next((path for path in map(shutil.which, names) if path), None)
