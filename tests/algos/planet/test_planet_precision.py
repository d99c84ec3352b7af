"""PlaNet's learner precision: `auto` times fp32 and bf16 and keeps the faster (fp32 where the
CPU has no native bf16), a resumed learner keeps the choice, and a bf16 update's losses stay
within the latent-sampling noise of fp32's."""
import numpy as np
import torch

from wmdist.algos.planet import PlaNet, PlaNetConfig
from wmdist.bench.dreamer import random_batch
from wmdist.envs.spec import EnvSpec

SPEC = EnvSpec("test:cont", (5,), "float32", "vector", action_shape=(1,), action_low=(-1.0,), action_high=(1.0,))


def _cfg(**kw) -> PlaNetConfig:
    return PlaNetConfig(deter=16, stoch=4, units=16, free_nats=0.0, **kw)


def test_auto_measures_both_precisions_records_the_choice_and_a_resumed_learner_keeps_it():
    learner = PlaNet(SPEC, _cfg(precision="auto", precision_trials=1)).make_learner()
    learner.precision.reason, learner.precision.choice = "", {}  # measure on any CPU
    batch = random_batch(SPEC, 2, 6)
    metrics = [learner.update(batch).metrics for _ in range(4)]
    assert [m["bf16_world_model"] for m in metrics] == [0, 1, 0, 1]  # warm-up in each, then one timed each
    assert learner.precision.choice["world_model"] in ("fp32", "bf16") and not learner.precision.measuring
    assert "precision_world_model_bf16_s" in metrics[-1] and "bf16_actor_critic" not in metrics[-1]
    resumed = PlaNet(SPEC, _cfg(precision="auto")).make_learner()
    resumed.precision.choice = {}
    resumed.load_state_dict(learner.state_dict())
    assert resumed.precision.choice == learner.precision.choice


def test_auto_without_native_bf16_is_fp32_from_the_first_update(monkeypatch):
    monkeypatch.setattr("wmdist.algos.dreamer.precision.native_bf16", lambda device: False)
    learner = PlaNet(SPEC, _cfg(precision="auto")).make_learner()
    assert not learner.precision.measuring
    assert learner.update(random_batch(SPEC, 2, 6)).metrics["bf16_world_model"] == 0.0


def _losses(precision: str, seed: int) -> np.ndarray:
    learner = PlaNet(SPEC, _cfg(precision=precision), seed=0).make_learner()
    learner.generator.manual_seed(seed)
    m = learner.update(random_batch(SPEC, 4, 10, seed=3)).metrics
    return np.array([m[k] for k in ("model_loss", "recon_loss", "reward_loss", "kl")])


def test_a_bf16_update_stays_within_sampling_noise_of_fp32():
    torch.set_num_threads(1)
    fp32 = np.stack([_losses("fp32", s) for s in range(4)])  # [seeds, losses]
    bf16 = np.stack([_losses("bf16", s) for s in range(4)])
    assert bf16[:, 0].tolist() != fp32[:, 0].tolist()  # the bf16 path ran
    noise = fp32.std(0) + 1e-3 * np.abs(fp32.mean(0))
    gap = np.abs(bf16 - fp32).mean(0)
    assert np.all(gap < 3 * noise + 0.02 * np.abs(fp32.mean(0)) + 1e-4), (gap, noise)


def test_the_bench_times_both_precisions_where_bf16_is_native():
    from wmdist.algos.dreamer.precision import native_bf16
    from wmdist.bench.planner import learner_precision

    row = learner_precision(1)
    assert row["case"] == "learner_precision" and row["batch"] == "50x50"
    if native_bf16(torch.device("cpu")):
        assert row["seconds_per_update_fp32"] > 0 and row["seconds_per_update_bf16"] > 0
        # the ratio of the unrounded times, to 2 decimals; the times are printed rounded to 0.1 ms, so the
        # ratio recomputed from them can differ in the last digit
        ratio = row["seconds_per_update_fp32"] / row["seconds_per_update_bf16"]
        assert abs(row["bf16_speedup"] - ratio) < 0.011
    else:  # not timed: bf16 without native support is far slower, and auto never picks it
        assert "bf16_speedup" not in row
