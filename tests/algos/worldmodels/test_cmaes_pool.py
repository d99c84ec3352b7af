"""CMA-ES with the evaluation pool: it finds a shifted sphere's optimum, a killed evaluation
actor costs no candidate, and the search state survives a save as arrays."""
import numpy as np
import pytest
import torch

from wmdist.algos.worldmodels.cmaes import CMAES
from wmdist.algos.worldmodels.pool import EvalPool, PoolFailed
from wmdist.runtime.calls import LocalHandle

from tests.algos.worldmodels.sphere_worker import SHIFT, SphereWorker

MODEL = {"scale": np.array(1.0)}


def _search(pool: EvalPool, generations: int, seed: int = 0, checks=None) -> CMAES:
    es = CMAES(dim=5, popsize=8, sigma0=1.0, seed=seed)
    for _ in range(generations):
        x = es.ask()
        f = pool.evaluate(x, np.arange(2), model_id=7, model=lambda: MODEL)
        assert not np.isnan(f).any()  # every candidate scored
        np.testing.assert_allclose(f, -np.sum((x - SHIFT) ** 2, 1), rtol=1e-4, atol=1e-6)  # as itself (sent as float32)
        es.tell(x, f)
    return es


def test_finds_the_shifted_sphere_with_local_actors():
    pool = EvalPool([LocalHandle(SphereWorker(i)) for i in range(3)])
    es = _search(pool, 120)
    assert np.abs(es.best_x - SHIFT).max() < 1e-3 and es.best_f > -1e-6
    # each actor got the model in the first generation (once per share it already had queued), never again
    assert 3 <= pool.model_loads <= 4 and pool.retries == 0


def test_state_as_arrays_rebuilds_the_search():
    pool = EvalPool([LocalHandle(SphereWorker(0))])
    es = _search(pool, 10)
    state = {k: torch.from_numpy(np.atleast_1d(v)) for k, v in es.state().items()}  # as a checkpoint holds it
    again = CMAES(dim=5, popsize=8, sigma0=1.0, seed=0)
    again.load(state)
    assert again.generation == 10 and again.sigma == pytest.approx(es.sigma)
    np.testing.assert_allclose(again.mean, es.mean)
    np.testing.assert_allclose(again.es.sm.C, es.es.sm.C)
    for _ in range(110):
        x = again.ask()
        again.tell(x, -np.sum((x - SHIFT) ** 2, 1))
    assert np.abs(again.best_x - SHIFT).max() < 1e-3
    with pytest.raises(ValueError, match="population 8"):
        CMAES(dim=5, popsize=6, sigma0=1.0).load(state)


def test_population_below_the_cma_minimum_is_refused():
    with pytest.raises(ValueError, match="population must be >= 2"):
        CMAES(dim=5, popsize=1, sigma0=1.0)


def test_a_share_that_keeps_failing_ends_in_one_line():
    class Broken(SphereWorker):
        def evaluate(self, *args):
            raise RuntimeError("boom")

    pool = EvalPool([LocalHandle(Broken(0))], max_retries=2)
    with pytest.raises(PoolFailed, match="failed 3 times; last: boom"):
        pool.evaluate(np.zeros((4, 5)), np.arange(1), model_id=1, model=lambda: MODEL)


def test_a_killed_actor_costs_no_candidate_on_ray(ray_session, tmp_path):
    ray = ray_session
    marker = tmp_path / "died"
    cls = ray.remote(SphereWorker).options(num_cpus=0.1, max_restarts=-1, max_task_retries=0)
    actors = [cls.remote(0, str(marker)), cls.remote(1)]
    pids = ray.get([a.pid.remote() for a in actors])
    pool = EvalPool(actors, max_retries=4)
    es = _search(pool, 120)
    assert marker.exists(), "actor 0 never died: the test did not test anything"
    assert pool.retries >= 1
    assert np.abs(es.best_x - SHIFT).max() < 1e-3
    assert ray.get(actors[0].pid.remote()) != pids[0]  # Ray restarted it, and it was sent the model again
    assert pool.model_loads >= 3
    for a in actors:
        ray.kill(a)


def test_a_killed_dream_actor_is_restarted_and_its_share_scored_the_same(ray_session):
    """The role's own actor class (`wm_eval`): killing one mid-generation changes no fitness,
    since a share's dream depends only on its candidates and the rollout seeds."""
    import dataclasses
    import threading
    import time

    from wmdist.algos.worldmodels import WorldModelsConfig
    from wmdist.algos.worldmodels.worker import EvalWorker
    from wmdist.bench.cmaes import SPEC, _model

    ray = ray_session
    cfg = dataclasses.replace(WorldModelsConfig(), dream_max_steps=1000, popsize=8, rollouts=2)
    model = _model(cfg)  # M never says done: every dream runs its 1000 steps (~0.5 s a share on a quiet core)
    cls = ray.remote(EvalWorker).options(num_cpus=0.1, max_restarts=-1, max_task_retries=0)
    actors = [cls.remote(None, SPEC, i, 1, algo_config=cfg) for i in range(2)]
    pids = ray.get([a.pid.remote() for a in actors])
    params = np.random.default_rng(0).normal(0, 0.1, (8, (32 + 256) * 3 + 3))
    seeds = np.arange(2)
    pool = EvalPool(actors, shares_per_actor=1)
    calm = pool.evaluate(params, seeds, 1, lambda: model)
    killer = threading.Timer(0.05, lambda: ray.kill(actors[0], no_restart=False))  # mid-share
    killer.start()
    t0 = time.monotonic()
    again = pool.evaluate(params, seeds, 1, lambda: model)
    killer.join()
    assert time.monotonic() - t0 > 0.05, "the generation ended before the kill: nothing was tested"
    assert pool.retries >= 1
    np.testing.assert_array_equal(again, calm)  # no candidate lost, none scored differently
    deadline = time.monotonic() + 60
    while True:  # the actor may still be coming back (its share went to the other one)
        try:
            assert ray.get(actors[0].pid.remote()) != pids[0]
            break
        except ray.exceptions.ActorUnavailableError:
            assert time.monotonic() < deadline, "the killed actor never came back"
            time.sleep(0.5)
    for a in actors:
        ray.kill(a)


def test_the_pool_role_asks_ray_for_the_configured_node_resources():
    """`algo.eval_actor_resources` reaches the `wm_eval` role's actor options (placement on tagged nodes)."""
    from pathlib import Path

    from wmdist.algos.worldmodels.algo import WorldModels
    from wmdist.config.loader import load_config

    preset = Path(__file__).parents[3] / "configs" / "worldmodels_carracing.yaml"
    cfg = load_config(str(preset), ["algo.eval_actor_resources={eval_node: 1}", "algo.eval_actor_cpus=0.5"])
    (role,) = WorldModels.extra_roles(cfg)
    assert role.resources_of(cfg).options() == {"num_cpus": 0.5, "num_gpus": 0.0, "resources": {"eval_node": 1}}
    assert "resources" not in role.resources_of(load_config(str(preset))).options()  # none unless configured
