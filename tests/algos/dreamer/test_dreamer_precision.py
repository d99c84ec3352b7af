"""Per-phase precision: the auto choice (fake clock), its record in metrics and checkpoints,
and each phase in bf16 keeping the losses within the sampling noise of fp32.
Phase times are given to `end_update` directly: no test here depends on this machine's speed."""
import numpy as np
import pytest
import torch

from dreamer_loop import tiny_config
from wmdist.algos.dreamer import Dreamer
from wmdist.algos.dreamer.precision import PHASES, PhasePrecision
from wmdist.bench.dreamer import bench_spec, random_batch


def _run(prec: PhasePrecision, cost: dict[str, dict[str, float]], updates: int) -> list[dict[str, float]]:
    out = []
    for _ in range(updates):
        spent = {p: cost[p][prec.mode(p)] for p in PHASES}
        out.append(prec.end_update(spent))
    return out


def test_auto_keeps_the_faster_precision_per_phase_after_warmup_and_trials():
    prec = PhasePrecision({"world_model": "auto", "actor_critic": "auto"}, torch.device("cpu"), trials=2, bf16_ok=True)
    assert prec.mode("world_model") == "fp32" and prec.measuring
    cost = {"world_model": {"fp32": 2.0, "bf16": 1.0}, "actor_critic": {"fp32": 1.0, "bf16": 3.0}}
    metrics = _run(prec, cost, 6)  # warm-up fp32, bf16, then 2 trials of each, alternating
    assert [m["bf16_world_model"] for m in metrics] == [0, 1, 0, 1, 0, 1]
    assert prec.choice == {"world_model": "bf16", "actor_critic": "fp32"} and not prec.measuring
    assert metrics[-1]["precision_world_model_fp32_s"] == 2.0 and metrics[-1]["precision_actor_critic_bf16_s"] == 3.0
    later = _run(prec, cost, 3)
    assert all(m == {"bf16_world_model": 1.0, "bf16_actor_critic": 0.0} for m in later)


def test_auto_ignores_the_warmup_update():
    prec = PhasePrecision({"world_model": "auto", "actor_critic": "fp32"}, torch.device("cpu"), trials=1, bf16_ok=True)
    prec.end_update({"world_model": 100.0})  # fp32 warm-up: slow (allocation), not counted
    prec.end_update({"world_model": 1.0})  # bf16 warm-up
    prec.end_update({"world_model": 1.0})  # fp32
    prec.end_update({"world_model": 2.0})  # bf16
    assert prec.choice == {"world_model": "fp32", "actor_critic": "fp32"}


def test_auto_without_native_bf16_is_fp32_at_once_and_fixed_modes_never_measure():
    prec = PhasePrecision({"world_model": "auto", "actor_critic": "bf16"}, torch.device("cpu"), bf16_ok=False)
    assert prec.choice == {"world_model": "fp32", "actor_critic": "bf16"} and not prec.measuring
    assert "no native bf16" in prec.describe()
    with pytest.raises(ValueError):
        PhasePrecision({"world_model": "fp16", "actor_critic": "fp32"}, torch.device("cpu"))


def test_learner_records_the_auto_choice_and_a_resumed_learner_keeps_it():
    spec = bench_spec(False)
    cfg = tiny_config(3, horizon=3, precision_world_model="auto", precision_actor_critic="auto", precision_trials=1)
    learner = Dreamer(spec, cfg).make_learner()
    learner.precision.reason, learner.precision.choice = "", {}  # measure even on a CPU without native bf16
    batch = random_batch(spec, 2, 6)
    metrics = [learner.update(batch).metrics for _ in range(4)]
    assert [m["bf16_actor_critic"] for m in metrics] == [0, 1, 0, 1]
    assert set(learner.precision.choice) == set(PHASES)
    assert "precision_world_model_fp32_s" in metrics[-1]
    resumed = Dreamer(spec, cfg).make_learner()
    resumed.precision.choice = {}
    resumed.load_state_dict(learner.state_dict())
    assert resumed.precision.choice == learner.precision.choice and not resumed.precision.measuring


def test_bf16_flag_sets_both_phases_and_an_explicit_phase_overrides_it():
    spec = bench_spec(True)
    # with the critic replay loss on, the bf16 replay states are handed over too
    learner = Dreamer(spec, tiny_config(3, bf16=True, precision_actor_critic="fp32", repval_scale=0.3)).make_learner()
    assert learner.precision.choice == {"world_model": "bf16", "actor_critic": "fp32"}
    m = learner.update(random_batch(spec, 2, 6)).metrics
    assert m["bf16_world_model"] == 1.0 and m["bf16_actor_critic"] == 0.0
    assert np.isfinite(m["repval_loss"])


def _losses(discrete: bool, wm: str, ac: str, seed: int) -> np.ndarray:
    spec = bench_spec(discrete)
    cfg = tiny_config(3, horizon=5, precision_world_model=wm, precision_actor_critic=ac)
    learner = Dreamer(spec, cfg, seed=0).make_learner()
    learner.generator.manual_seed(seed)
    m = learner.update(random_batch(spec, 4, 10, seed=3)).metrics
    return np.array([m[k] for k in ("model_loss", "recon_loss", "reward_loss", "critic_loss", "actor_loss")])


@pytest.mark.parametrize("discrete", [True, False])
@pytest.mark.parametrize("wm,ac", [("bf16", "fp32"), ("fp32", "bf16"), ("bf16", "bf16")])
def test_each_phase_in_bf16_stays_within_sampling_noise_of_fp32(discrete, wm, ac):
    torch.set_num_threads(1)
    fp32 = np.stack([_losses(discrete, "fp32", "fp32", s) for s in range(4)])  # [seeds, losses]
    mixed = np.stack([_losses(discrete, wm, ac, s) for s in range(4)])
    noise = fp32.std(0) + 1e-3 * np.abs(fp32.mean(0))  # spread from latent / imagination sampling alone
    gap = np.abs(mixed - fp32).mean(0)
    assert np.all(gap < 3 * noise + 0.02 * np.abs(fp32.mean(0)) + 1e-4), (gap, noise)
