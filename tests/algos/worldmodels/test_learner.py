"""The staged learner (V, then M, then CMA-ES generations), its checkpoint as tensors and
arrays only, a whole local run that resumes its evolution, `wmdist dream`, and bad input."""
import io
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from wmdist.algos.worldmodels import WorldModels, WorldModelsConfig
from wmdist.config.loader import load_config
from wmdist.envs import EnvConfig, make_env
from wmdist.envs.spec import EnvSpec
from wmdist.runtime import checkpoint as ck
from wmdist.runtime.checkpoint import _tensorise
from wmdist.runtime.train import train

CONFIGS = Path(__file__).parents[3] / "configs"
SPEC = EnvSpec(id="test", obs_shape=(64, 64, 3), obs_dtype="uint8", obs_kind="image", num_actions=3)
SMALL = dict(vae_updates=2, rnn_updates=2, popsize=4, rollouts=2, eval_actors=0, dream_max_steps=40,
             rnn_hidden=16, vae_depth=4, vae_frames=8)


def _batch(seed: int = 0, b: int = 2, t: int = 6) -> dict:
    rng = np.random.default_rng(seed)
    first = np.zeros((b, t), bool)
    first[:, 0] = True
    terminal = np.zeros((b, t), bool)
    terminal[0, -1] = True
    return {"obs": rng.integers(0, 255, (b, t, 64, 64, 3), dtype=np.uint8), "action": rng.integers(0, 3, (b, t)),
            "reward": np.ones((b, t), np.float32), "first": first, "last": terminal.copy(), "terminal": terminal,
            "mask": np.ones((b, t), np.float32), "is_weight": np.ones(b)}


def test_stages_in_order_and_the_checkpoint_resumes_the_evolution():
    algo = WorldModels(SPEC, WorldModelsConfig(**SMALL))
    learner = algo.make_learner()
    stages = [learner.update(_batch(i)).metrics for i in range(6)]
    assert [m["stage"] for m in stages] == [0, 0, 1, 1, 2, 2]
    assert "vae_kl" in stages[0] and "rnn_nll" in stages[2] and "rnn_done_loss" in stages[2]
    assert stages[5]["cma_generation"] == 2 and stages[5]["cma_best_fitness"] >= 1  # survived at least one dream step
    w = learner.get_weights()
    assert float(w["has_controller"]) == 1 and w["controller"].shape == ((32 + 16) * 3 + 3,)
    # as the runtime stores it: tensors, loaded with weights_only=True (no unpickled objects)
    buf = io.BytesIO()
    torch.save(_tensorise(learner.state_dict()), buf)
    buf.seek(0)
    state = torch.load(buf, weights_only=True)
    again = algo.make_learner()
    again.load_state_dict(state)
    assert again.updates == 6 and again.cma.generation == 2
    np.testing.assert_allclose(again.cma.mean, learner.cma.mean)
    np.testing.assert_allclose(again.cma.es.sm.C, learner.cma.es.sm.C)
    np.testing.assert_array_equal(again.get_weights()["controller"], w["controller"])
    assert again.update(_batch(9)).metrics["cma_generation"] == 3  # the evolution goes on


def test_the_policy_acts_at_random_then_with_the_controller():
    algo = WorldModels(SPEC, WorldModelsConfig(**SMALL))
    learner, policy = algo.make_learner(), algo.make_policy()
    obs, first = _batch()["obs"][:, 0], np.array([True, True])
    policy.set_weights(learner.get_weights(), 0)
    assert policy.controller is None
    for i in range(5):
        learner.update(_batch(i))
    policy.set_weights(learner.get_weights(), 1)
    a, extras = policy.act(obs, first, None, None, explore=False)
    assert a.shape == (2,) and a.dtype == np.int64 and extras == {}
    assert policy.state[0].shape == (1, 2, 16)  # M's state carried per env


@pytest.mark.parametrize("override,message", [
    ("algo.popsize=1", "algo.popsize must be >= 2 (the CMA-ES minimum), got 1"),
    ("algo.temperature=0", "algo.temperature (tau) must be > 0, got 0"),
    ("algo.temperature=-1.5", "algo.temperature (tau) must be > 0, got -1.5"),
    ("algo.rnn_updates=0", "algo.train_in is dream but algo.rnn_updates is 0: a controller trained in the dream needs a trained M"),
])
def test_bad_input_is_one_line(tmp_path, override, message):
    with pytest.raises(Exception) as err:  # refused by the loader or by train's checks, before anything starts
        train(cfg=load_config(CONFIGS / "worldmodels_doom_takecover.yaml", [f"run.dir={tmp_path}", override]),
              out=io.StringIO())
    assert message in str(err.value) and "\n" not in str(err.value)
    assert not any(tmp_path.iterdir())  # nothing started, nothing written


def test_non_image_env_is_refused():
    with pytest.raises(ValueError, match="needs 64x64 image observations"):
        WorldModels(EnvSpec(id="gym:CartPole-v1", obs_shape=(4,), obs_dtype="float32", obs_kind="vector", num_actions=2))


def test_local_run_reaches_the_search_and_resume_continues_it(tmp_path):
    quiet = ["metrics.enabled=false", "metrics.tensorboard=false", "eval.every_seconds=0", "checkpoint.every_seconds=0",
             "run.max_minutes=3", "replay.min_size=60", "learner.batch_size=2", "replay.seq_len=8", "replay.overlap=2",
             "actors.envs_per_actor=2", "algo.vae_updates=2", "algo.rnn_updates=2", "algo.popsize=4", "algo.rollouts=2",
             "algo.vae_frames=8", "algo.dream_max_steps=30", "algo.eval_actors=2", "ray.local=true",
             "algo.reeval_every=2", "algo.reeval_rollouts=2"]  # re-scored through the pool at generations 2 and 4
    cfg = load_config(CONFIGS / "worldmodels_doom_takecover.yaml", [f"run.dir={tmp_path}", *quiet, "run.max_updates=7"])
    assert train(cfg=cfg, out=io.StringIO()) == 0
    run = next(p for p in tmp_path.iterdir() if p.is_dir())
    state = ck.load_learner_state(ck.latest_checkpoint(run))["learner"]
    assert int(np.asarray(state["cma"]["generation"]).reshape(-1)[0]) == 3
    assert train(resume=str(run), overrides=["run.max_updates=9"], out=io.StringIO()) == 0
    state = ck.load_learner_state(ck.latest_checkpoint(run))["learner"]
    assert int(np.asarray(state["cma"]["generation"]).reshape(-1)[0]) == 5
    assert np.isfinite(float(np.asarray(state["pick"]["f"]).reshape(-1)[0]))  # the published pick was resumed
    records = [json.loads(line) for line in (run / "metrics.jsonl").read_text().splitlines()]
    assert any("loss/cma_best_fitness" in r for r in records)
    assert sum("loss/pick_fitness" in r for r in records) >= 1
    # `wmdist dream RUN --check`: the controller and each fixed action, in the dream and the real game
    from wmdist.runtime.evaluate import dream_check_run

    out = io.StringIO()
    assert dream_check_run(str(run), rollouts=2, episodes=1, stream=out) == 0
    rows = json.loads((run / "dream_check.json").read_text())["rows"]
    assert [r["policy"] for r in rows] == ["controller", "always action 0", "always action 1", "always action 2"]
    assert all(1 <= r["dream"] <= 30 and r["real"] >= 1 for r in rows)  # dreams capped at 30 steps here
    assert "always action 2" in out.getvalue()


def test_dream_video_writes_real_beside_predicted(tmp_path):
    algo = WorldModels(SPEC, WorldModelsConfig(**SMALL))
    learner = algo.make_learner()
    with make_env(EnvConfig(id="vizdoom:TakeCover"), seed=0) as env:
        algo.spec = env.spec
        path = algo.dream_video(learner.get_weights(), env, str(tmp_path / "dream.gif"), context=3, horizon=4)
    import imageio.v2 as imageio

    # 3 + 4 steps, real | predicted side by side; the GIF writer merges identical consecutive frames, so at most 7
    frames = imageio.mimread(path)
    assert len(frames) <= 7 and frames[0].shape[:2] == (64 * 4, 128 * 4)
    for f in frames:  # each a 64 x 128 picture scaled up 4x: every 4x4 block is one pixel's colour
        rgb = np.asarray(f)[..., :3]
        assert np.array_equal(rgb, np.repeat(np.repeat(rgb[::4, ::4], 4, 0), 4, 1))
    from wmdist.algos.worldmodels.dream import predict_frames

    obs = np.zeros((7, 64, 64, 3), np.uint8)
    preds = predict_frames(algo, learner.get_weights(), obs, np.zeros(7, np.int64), context=3)
    assert preds.shape == (7, 64, 64, 3) and preds.dtype == np.uint8


def test_carracing_preset_searches_in_the_real_env(tmp_path):
    """The CarRacing preset's controller search scores candidates in real episodes (train_in: real)."""
    quiet = ["metrics.enabled=false", "metrics.tensorboard=false", "eval.every_seconds=0", "checkpoint.every_seconds=0",
             "run.max_minutes=3", "replay.min_size=60", "learner.batch_size=2", "replay.seq_len=8", "replay.overlap=2",
             "actors.envs_per_actor=1", "algo.vae_updates=2", "algo.rnn_updates=2", "algo.popsize=2", "algo.rollouts=1",
             "algo.vae_frames=8", "algo.real_max_steps=15", "algo.eval_actors=1", "ray.local=true", "run.max_updates=6"]
    cfg = load_config(CONFIGS / "worldmodels_carracing.yaml", [f"run.dir={tmp_path}", *quiet])
    assert train(cfg=cfg, out=io.StringIO()) == 0
    run = next(p for p in tmp_path.iterdir() if p.is_dir())
    state = ck.load_learner_state(ck.latest_checkpoint(run))["learner"]
    assert int(np.asarray(state["cma"]["generation"]).reshape(-1)[0]) == 2
    best = float(np.asarray(state["cma"]["best_f"]).reshape(-1)[0])
    assert np.isfinite(best) and best != 0.0  # a real return over 15 steps (tiles and the -0.1 per frame)
