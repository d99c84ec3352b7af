"""Dreamer learner speed: gradient updates/s of the small V3 model on CPU, fp32, bf16 and auto.

`auto` is both phases (world model; imagination + actor-critic) on `precision_*: auto`: after
its start-up measurement it runs each phase in the precision it timed faster (issue 21:
never slower than fp32).

Target (issue 7): at least 2 updates/s for this model and batch.

Model: units 256, GRU 256, 32 x 32 latents, 2-layer MLPs; batch 16 x 64; imagination of
H = 15 from all 1024 posterior states. Two action kinds: discrete (REINFORCE, dynamics run
without autograd) and continuous (gradients through the dynamics). Each case also reports
where the time goes (world model / imagination / actor / critic, from a wall-clock split
of one update) and the top ops of a torch.profiler run. Further cases: the CartPole
preset's model (units/GRU 128, batch 16 x 32), the two-hot loss + mean as gathered
bins against the dense reference, timed side by side, and each time-bound preset's learner
at 1 and 2 torch threads (what `learner.cpus: 2` buys where the other roles leave a core
mostly idle).
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
import torch

from wmdist.algos.dreamer import Dreamer, DreamerConfig
from wmdist.envs.spec import EnvSpec
from wmdist.runtime.malloc import tune_malloc

CONFIGS = Path(__file__).parents[2] / "configs"
# presets whose runs end at their time budget with the learner as the bottleneck
THREAD_PRESETS = ("dreamerv1_dmc_cartpole_balance", "dreamerv3_dmc_cartpole_balance", "dreamerv3_minatar_breakout")


def small_v3(bf16: bool, **over) -> DreamerConfig:
    return DreamerConfig(version=3, deter=256, units=256, mlp_layers=2, stoch=32, classes=32, bf16=bf16, **over)


def _auto_learner(spec: EnvSpec, trials: int):
    """A learner with both phases on `auto`, its start-up measurement done on the bench batch."""
    return Dreamer(spec, small_v3(False, precision_world_model="auto", precision_actor_critic="auto",
                                  precision_trials=trials)).make_learner()


def _finish_measuring(learner, batch) -> int:
    """Runs `auto`'s start-up updates; returns how many it took."""
    n = 0
    while learner.precision.measuring:
        learner.update(batch)
        n += 1
    return n


def bench_spec(discrete: bool) -> EnvSpec:
    if discrete:  # CartPole-like
        return EnvSpec("bench:discrete", (4,), "float32", "vector", num_actions=2)
    return EnvSpec("bench:continuous", (5,), "float32", "vector", action_shape=(1,), action_low=(-1.0,), action_high=(1.0,))


def random_batch(spec: EnvSpec, b: int, t: int, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    if spec.discrete:
        action = rng.integers(0, spec.num_actions, (b, t)).astype(np.int64)
    else:
        action = rng.uniform(-1, 1, (b, t, spec.action_dim)).astype(np.float32)
    first = np.zeros((b, t), bool)
    first[:, 0] = True
    return {
        "obs": rng.normal(size=(b, t, *spec.obs_shape)).astype(np.float32),
        "action": action,
        "reward": rng.uniform(0, 1, (b, t)).astype(np.float32),
        "first": first,
        "last": np.zeros((b, t), bool),
        "terminal": np.zeros((b, t), bool),
        "mask": np.ones((b, t), bool),
        "is_weight": np.ones(b, np.float32),
    }


def _split(learner, batch) -> dict[str, float]:
    """Wall time of each phase of one update (forward + its backward), in seconds."""
    t = learner._tensors(batch)
    out = {}
    with learner._autocast():
        t0 = time.perf_counter()
        model_loss, _, start = learner.world_model_loss(t)
        t1 = time.perf_counter()
        actor_loss, critic_loss, _ = learner.ac_loss(start, learner.generator)
        t2 = time.perf_counter()
    learner.actor_opt(actor_loss)
    t3 = time.perf_counter()
    learner.critic_opt(critic_loss)
    t4 = time.perf_counter()
    learner.wm_opt(model_loss)
    t5 = time.perf_counter()
    out["world_model_fwd"] = t1 - t0
    out["imagination_and_ac_fwd"] = t2 - t1
    out["actor_bwd_step"] = t3 - t2
    out["critic_bwd_step"] = t4 - t3
    out["world_model_bwd_step"] = t5 - t4
    return out


def _top_ops(learner, batch, k: int = 8) -> list[dict]:
    from torch.profiler import ProfilerActivity, profile

    with profile(activities=[ProfilerActivity.CPU]) as prof:
        learner.update(batch)
    rows = sorted(prof.key_averages(), key=lambda e: e.self_cpu_time_total, reverse=True)[:k]
    return [{"op": r.key, "self_ms": round(r.self_cpu_time_total / 1e3, 1), "calls": r.count} for r in rows]


def _matmul_gflops(dtype: torch.dtype, m: int = 1024, k: int = 256, n: int = 768, reps: int = 5) -> float:
    a, b = torch.randn(m, k, dtype=dtype), torch.randn(k, n, dtype=dtype)
    a @ b
    t0 = time.perf_counter()
    for _ in range(reps):
        a @ b
    return 2 * m * k * n * reps / (time.perf_counter() - t0) / 1e9


def _update_flops(learner, batch) -> float:
    """Matmul/conv FLOPs of one update as counted by torch (embedding bags are not counted)."""
    from torch.utils.flop_counter import FlopCounterMode

    with FlopCounterMode(display=False) as counter:
        learner.update(batch)
    return counter.get_total_flops()


def _twohot_case(n: int = 7680, reps: int = 5) -> dict:
    """Critic-sized two-hot loss (forward + backward): gathered bins vs the dense target."""
    from wmdist.nets.dists import symlog, twohot_bins, twohot_encode, twohot_loss

    bins = twohot_bins()
    g = torch.Generator().manual_seed(0)
    logits = torch.randn(n, len(bins), generator=g, requires_grad=True)
    y = torch.randn(n, generator=g) * 30

    def dense():
        loss = -(twohot_encode(symlog(y), bins) * torch.log_softmax(logits, -1)).sum(-1)
        loss.mean().backward()

    def ours():
        twohot_loss(logits, y, bins).mean().backward()

    times = {"dense": 0.0, "ours": 0.0}
    dense(), ours()  # warm-up
    for _ in range(reps):  # interleaved, so load changes hit both alike
        for name, fn in (("dense", dense), ("ours", ours)):
            t0 = time.perf_counter()
            fn()
            times[name] += time.perf_counter() - t0
    return {"case": "twohot_loss_vs_dense", "rows": n, "bins": len(bins),
            "dense_ms": round(1e3 * times["dense"] / reps, 2), "ours_ms": round(1e3 * times["ours"] / reps, 2),
            "speedup": round(times["dense"] / times["ours"], 2)}


def _imag_starts_case(b: int, t: int, quick: bool) -> dict:
    """The dm_control preset's model (continuous, backprop through the dynamics): imagining
    from every posterior state vs from 128 of them, updates interleaved."""
    spec = bench_spec(False)
    batch = random_batch(spec, b, t)
    starts = {"all": 0, "128": 128}
    learners = {k: Dreamer(spec, DreamerConfig(version=3, deter=128, units=128, mlp_layers=2, stoch=32, classes=32,
                                              imag_starts=n)).make_learner() for k, n in starts.items()}
    times = _time_side_by_side(learners, batch, 1 if quick else 3)
    return {"case": "v3_dmc_preset_continuous_imag_starts", "units": 128, "deter": 128, "batch": f"{b}x{t}",
            "seconds_per_update_all_starts": round(times["all"], 3),
            "seconds_per_update_128_starts": round(times["128"], 3),
            "speedup": round(times["all"] / times["128"], 2)}


def _time_side_by_side(learners: dict, batch, updates: int,
                       before: Callable[[object], None] | None = None) -> dict:
    """Seconds per update of each learner, updates interleaved so load changes hit all alike.
    `before(key)`, if given, runs ahead of each of that key's updates, untimed (e.g. to set
    the thread count one key stands for)."""
    for k, learner in learners.items():
        if before:
            before(k)
        learner.update(batch)  # warm-up
    times = {k: 0.0 for k in learners}
    for _ in range(updates):
        for k, learner in learners.items():
            if before:
                before(k)
            t0 = time.perf_counter()
            learner.update(batch)
            times[k] += time.perf_counter() - t0
    return {k: v / updates for k, v in times.items()}


def _threads_case(preset: str, updates: int) -> dict:
    """One preset's learner on its own model, batch and env shapes, timed at 1 and 2 torch
    threads, updates interleaved so load changes hit both alike."""
    from wmdist.config.loader import load_config
    from wmdist.runtime.train import env_spec_or_error

    cfg = load_config(CONFIGS / f"{preset}.yaml")
    spec = env_spec_or_error(cfg)
    learner = Dreamer(spec, cfg.algo, seed=0).make_learner()
    batch = random_batch(spec, cfg.learner.batch_size, cfg.replay.seq_len)
    threads = torch.get_num_threads()
    try:  # one learner under two keys: the key is its thread count
        times = _time_side_by_side({1: learner, 2: learner}, batch, updates, before=torch.set_num_threads)
    finally:
        torch.set_num_threads(threads)
    return {"case": f"learner_threads_{preset}", "batch": f"{cfg.learner.batch_size}x{cfg.replay.seq_len}",
            "imag_starts": cfg.algo.imag_starts, "seconds_per_update_1_thread": round(times[1], 3),
            "seconds_per_update_2_threads": round(times[2], 3),
            "speedup_2_threads": round(times[1] / times[2], 2)}


def _loss_check(spec: EnvSpec, updates: int, b: int, t: int) -> dict:
    """Training losses in bf16 against fp32 beside the spread of fp32 itself.

    Three learners start from the same weights and see the same batches: fp32 with sampling
    seed 0, fp32 with seed 1, bf16 with seed 0. The fp32 pair's difference is the noise that
    latent and imagination sampling alone makes; bf16 passes if its distance from fp32 (seed
    0) stays within 3x that, averaged over the second half of the updates.
    """
    names = ("model_loss", "recon_loss", "reward_loss", "kl_dyn", "actor_loss", "critic_loss")
    runs = {"fp32_s0": (False, 0), "fp32_s1": (False, 1), "bf16_s0": (True, 0)}
    learners = {k: Dreamer(spec, small_v3(bf16), seed=0).make_learner() for k, (bf16, _) in runs.items()}
    init = learners["fp32_s0"].state_dict()
    curves: dict[str, list[list[float]]] = {k: [] for k in runs}
    for k, (_, seed) in runs.items():
        learners[k].load_state_dict(init)
        learners[k].generator.manual_seed(seed)
    for i in range(updates):
        batch = random_batch(spec, b, t, seed=100 + i)
        for k, learner in learners.items():
            m = learner.update(batch).metrics
            curves[k].append([m[n] for n in names])
    c = {k: np.array(v)[updates // 2:] for k, v in curves.items()}  # [updates/2, losses]
    noise = np.abs(c["fp32_s1"] - c["fp32_s0"]).mean(0)
    gap = np.abs(c["bf16_s0"] - c["fp32_s0"]).mean(0)
    return {"case": "v3_small_bf16_loss_check", "updates": updates, "batch": f"{b}x{t}",
            "fp32_last": dict(zip(names, np.round(np.array(curves["fp32_s0"][-1]), 4).tolist())),
            "fp32_seed_gap": dict(zip(names, np.round(noise, 4).tolist())),
            "bf16_gap": dict(zip(names, np.round(gap, 4).tolist())),
            "within_noise": bool(np.all(gap <= 3 * noise + 1e-3 * np.abs(c["fp32_s0"]).mean(0)))}


def run(quick: bool = False) -> Iterator[dict]:
    """The small V3 model in fp32 and bf16 side by side (both action kinds), its loss check,
    then the preset-sized and two-hot cases.

    With native bf16 matmuls (AVX-512 BF16 / AMX, or CUDA) both precisions run at the full
    batch. Without them bf16 is far slower (AVX2: ~70x per matmul), so it is measured at a
    reduced batch (2 x 16) next to fp32 at the same batch, or a full-size update would take
    minutes.
    """
    tune_malloc()  # what every learner process does (wmdist.runtime.roles.set_threads)
    threads = torch.get_num_threads()
    native = native_bf16()
    b, t = (4, 16) if quick else (16, 64)
    updates = 1 if quick else 3
    for discrete in (True, False):
        spec = bench_spec(discrete)
        batch = random_batch(spec, b, t)
        fp32 = Dreamer(spec, small_v3(False)).make_learner()
        bf16 = Dreamer(spec, small_v3(True)).make_learner()
        auto = _auto_learner(spec, 1 if quick else 2)
        auto_updates = _finish_measuring(auto, batch)  # without native bf16: none, fp32 at once
        if native:  # same batch: interleave the three
            bb, bt = b, t
            times = _time_side_by_side({"fp32": fp32, "bf16": bf16, "auto": auto}, batch, updates)
        else:
            bb, bt = 2, 16
            times = _time_side_by_side({"fp32": fp32, "auto": auto}, batch, updates)
            times.update(_time_side_by_side({"bf16": bf16}, random_batch(spec, bb, bt), 1))
        dt, dt16, dta = times["fp32"], times["bf16"], times["auto"]
        flops = _update_flops(fp32, batch)
        fast = bf16 if native else fp32
        yield {
            "case": f"v3_small_{'discrete' if discrete else 'continuous'}",
            "actor_grad": "reinforce" if discrete else "backprop",
            "batch": f"{b}x{t}", "imagination_starts": b * t, "horizon": 15, "threads": threads,
            "native_bf16": native,
            "fp32_updates_per_s": round(1.0 / dt, 3),
            "bf16_updates_per_s": round(1.0 / dt16, 3), "bf16_batch": f"{bb}x{bt}",
            "bf16_speedup": round(dt / dt16, 2) if native else None,
            "auto_updates_per_s": round(1.0 / dta, 3), "auto_speedup": round(dt / dta, 2),
            "auto_choice": dict(auto.precision.choice), "auto_measuring_updates": auto_updates,
            "target_updates_per_s": 2.0,
            "best_updates_per_s": round(1.0 / (min(dt, dt16, dta) if native else min(dt, dta)), 3),
            "matmul_gflop_per_update": round(flops / 1e9, 1), "fp32_achieved_gflops": round(flops / 1e9 / dt, 1),
            "phase_seconds": {k: round(v, 3) for k, v in _split(fast, batch).items()},
            "phase_precision": "bf16" if native else "fp32",
            "phase_seconds_fp32": {k: round(v, 3) for k, v in _split(fp32, batch).items()} if native else None,
            "top_ops": [] if quick else _top_ops(fast, batch),
        }
    spec = bench_spec(True)
    # without native bf16 a full-batch bf16 update takes ~30 s (AVX2): the check runs at 4 x 16
    yield _loss_check(spec, 4 if quick else 16, *((b, t) if native else (min(b, 4), min(t, 16))))
    # the CartPole preset's model and batch (what `configs/dreamerv3_cartpole.yaml` trains)
    cfg = DreamerConfig(version=3, deter=128, units=128, mlp_layers=2, stoch=32, classes=32)
    pb, pt = (4, 16) if quick else (16, 32)
    batch = random_batch(spec, pb, pt)
    learner = Dreamer(spec, cfg).make_learner()
    dt = _time_side_by_side({"fp32": learner}, batch, updates)["fp32"]
    yield {"case": "v3_cartpole_preset_discrete_fp32", "units": 128, "deter": 128, "batch": f"{pb}x{pt}",
           "threads": threads, "updates_per_s": round(1.0 / dt, 3), "seconds_per_update": round(dt, 3),
           "phase_seconds": {k: round(v, 3) for k, v in _split(learner, batch).items()}}
    yield _imag_starts_case(pb, pt, quick)
    yield _twohot_case(1024 if quick else 7680)
    for preset in THREAD_PRESETS[:1] if quick else THREAD_PRESETS:
        yield _threads_case(preset, 1 if quick else 5)
    yield {
        "case": "matmul_gflops", "shape": "1024x256 @ 256x768", "threads": threads, "native_bf16": native,
        "fp32": round(_matmul_gflops(torch.float32), 1),
        "bf16": round(_matmul_gflops(torch.bfloat16, reps=5 if native else 1), 1),
    }


def native_bf16() -> bool:
    """Whether this CPU multiplies bf16 in hardware (oneDNN's check: AVX-512 BF16 or AMX)."""
    return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
