"""A model too big for the machine is one line and exit 2 before anything starts.

Session 33 found `--set algo.value_support=1e8` accepted: the run started and its learner
died on an allocation of 51 GB. The check builds the learner on torch's meta device; these
tests hold it to the real model's size and to every preset, so it is never skipped unseen.
"""
from __future__ import annotations

from pathlib import Path

import pytest

from tests.runtime.one_line import one_line_exit_2
from wmdist.config.errors import ConfigError
from wmdist.config.loader import load_config
from wmdist.runtime import preflight as pf
from wmdist.runtime.preflight_memory import node_memory_bytes
from wmdist.runtime.preflight_model import check_model, measure, model_size, policy_copies

ROOT = Path(__file__).resolve().parents[2]
PRESETS = sorted(p for p in (ROOT / "configs").glob("*.yaml") if p.stem != "base")


def _algo(path: Path | str, sets: list[str] | None = None):
    cfg = load_config(str(path), sets or [])
    return cfg, pf.check_env_and_algo(cfg)[1]




def test_every_preset_is_measured_on_the_meta_device_and_fits_here():
    memory = node_memory_bytes()
    for path in PRESETS:
        cfg, algo = _algo(path)
        learner, policy = measure(algo)  # raises if a preset cannot be built on meta: the check would skip it
        assert learner.params > 0 and policy.params > 0, path.stem
        assert 4 * learner.params < learner.bytes_held and policy.bytes_held < learner.bytes_held, path.stem
        check_model(cfg, algo, memory=memory)


@pytest.mark.parametrize("preset", ["muzero_cartpole", "dreamerv3_cartpole", "efficientzero_cartpole",
                                    "planet_dmc_cartpole_swingup", "jepa_nav_tworooms"])
def test_the_meta_count_matches_the_real_learner(preset):
    _, algo = _algo(ROOT / "configs" / f"{preset}.yaml")
    meta, meta_policy = measure(algo)
    real, real_policy = model_size(algo.make_learner("cpu")), model_size(algo.make_policy("cpu"), trained_copies=1)
    assert (meta.params, meta.bytes_held, meta.largest) == (real.params, real.bytes_held, real.largest)
    assert (meta_policy.params, meta_policy.bytes_held) == (real_policy.params, real_policy.bytes_held)


def test_limit_by_hand_at_a_given_memory():
    cfg, algo = _algo(ROOT / "configs" / "muzero_cartpole.yaml")
    learner, policy = measure(algo)
    need = learner.bytes_held + policy_copies(cfg) * policy.bytes_held
    check_model(cfg, algo, memory=need)
    with pytest.raises(ConfigError, match="policy copies"):
        check_model(cfg, algo, memory=need - 1)
    more = load_config(str(ROOT / "configs" / "muzero_cartpole.yaml"), ["actors.num=3"])
    with pytest.raises(ConfigError):  # two more collectors each hold a policy
        check_model(more, algo, memory=need)
    joined = load_config(str(ROOT / "configs" / "muzero_cartpole.yaml"), ["ray.address=10.0.0.1:6379"])
    check_model(joined, algo, memory=1)  # a cluster's nodes are not this machine


@pytest.mark.parametrize("preset, sets, names", [
    ("muzero_cartpole", ["algo.value_support=100000000"], "value_head"),
    ("dreamerv3_cartpole", ["algo.deter=1000000"], "rssm.gru"),
    ("planet_dmc_cartpole_swingup", ["algo.units=1000000"], "["),
    ("worldmodels_doom_takecover", ["algo.z_dim=100000000"], "algo.z_dim"),
    # past what torch can even size on the meta device (the check used to skip it silently)
    ("dreamerv3_cartpole", ["algo.units=1000000000000"], "too large for torch to size"),
    # a layer count is bounded in the config: building 1e12 layers would never end
    ("dreamerv3_cartpole", ["algo.mlp_layers=1000000000000"], "algo.mlp_layers"),
])
def test_a_model_too_big_is_one_line_before_anything_starts(tmp_path, capsys, nothing_starts, preset, sets, names):
    line, _ = one_line_exit_2(capsys, ["train", str(ROOT / "configs" / f"{preset}.yaml"), "--set",
                                       f"run.dir={tmp_path}", *sets])
    assert names in line and ("memory" in line or "torch" in line or "out of range" in line)
    assert not any(tmp_path.iterdir()), "a run directory was created"
