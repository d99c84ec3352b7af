"""Collector: steps E envs with batched policy inference and writes complete sequences.

Driven by the driver one segment at a time (`run_segment`), so a collector that dies and
is restarted by Ray costs at most the segment it was in: its unfinished windows die with
it and were never visible in replay. Weights are pulled at every segment boundary (and
before the first action after a restart).
"""
from __future__ import annotations

import time
from typing import Any

import numpy as np

from wmdist.config.schema import RunConfig
from wmdist.envs.spec import EnvSpec
from wmdist.runtime.roles.setup import build_algorithm, device_for, process_tag, set_threads
from wmdist.runtime.roles.weights import pull


class Collector:
    def __init__(self, cfg: RunConfig, spec: EnvSpec, index: int, replay: Any, broker: Any, threads: int = 1) -> None:
        from wmdist.envs.vector import make_vector_env
        from wmdist.replay.writer import SequenceWriter

        set_threads(threads)
        self.cfg, self.index, self.replay, self.broker = cfg, index, replay, broker
        self.tag = process_tag()  # who answers (the driver counts restarts by it)
        self.incarnation = _incarnation(self.tag["restarted"])
        E = cfg.actors.envs_per_actor
        # a restarted collector must not replay its predecessor's random stream
        seed = cfg.run.seed * 1_000_003 + index * 10_007 + self.incarnation * 7_919
        self.algo = build_algorithm(cfg, spec, seed)
        self.policy = self.algo.make_policy(device_for(cfg.actors.gpus))
        self.venv = make_vector_env(cfg.env, E, seed)
        self.writer = SequenceWriter(self.algo.step_fields(), cfg.replay.seq_len, cfg.replay.overlap, E,
                                     pack=cfg.replay.pack_episodes)
        self.rng = np.random.default_rng(seed)
        self.step = self.venv.reset(seed=seed)
        self.version = -1
        self.pending: Any = None
        self.ep_return = np.zeros(E, np.float64)
        self.ep_length = np.zeros(E, np.int64)
        self.random_steps_left = cfg.actors.warmup_random_steps
        self._pull_weights(wait=True)

    # -- weights -------------------------------------------------------------------------
    def _pull_weights(self, wait: bool = False) -> None:
        deadline = time.monotonic() + 60.0
        while True:
            version, weights = pull(self.broker, self.version)
            if weights is not None:
                self.policy.set_weights(weights, version)
                self.version = version
                return
            if not wait or self.version >= 0 or time.monotonic() > deadline:
                return
            time.sleep(0.05)

    # -- acting --------------------------------------------------------------------------
    def _random_actions(self, legal: np.ndarray | None) -> np.ndarray:
        spec = self.venv.spec
        E = self.venv.num_envs
        if spec.discrete:
            if legal is None:
                return self.rng.integers(0, spec.num_actions, size=E)
            return np.array([self.rng.choice(np.flatnonzero(m)) for m in legal], np.int64)
        low, high = np.asarray(spec.action_low, np.float32), np.asarray(spec.action_high, np.float32)
        return self.rng.uniform(low, high, size=(E, *spec.action_shape)).astype(np.float32)

    def _act(self, explore: bool = True) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        s = self.step
        actions, extras = self.policy.act(s.obs, s.first, s.legal, s.to_play, explore)
        if self.random_steps_left > 0:
            actions = self._random_actions(s.legal)
            self.policy.taken(actions)  # a recurrent policy's next step conditions on these
            self.random_steps_left -= len(actions)  # env steps: one per env of this batched call
        return np.asarray(actions), extras

    def _flush(self, timeout: float) -> bool:
        """Insert pending sequences (replay drops those past `replay.max_policy_lag`, counted)."""
        if self.pending is None:
            return True
        if self.replay.insert(self.pending, source_id=self.index, timeout=timeout):
            self.pending = None
            return True
        return False

    def run_segment(self, env_steps: int = 0, updates: int = 0, explore: bool = True) -> dict:
        """Step every env `actors.segment_steps` times (unless the limiter holds us back).
        `explore=False` (tests, the local session) acts greedily, e.g. without root noise."""
        t0 = time.monotonic()
        stats: dict[str, Any] = {"index": self.index, "env_steps": 0, "episodes": [], "lengths": [],
                                 "inserted": 0, "limiter_blocked": False, **self.tag}
        held = 0 if self.pending is None else len(self.pending)  # left from a segment the limiter held back
        if not self._flush(self.cfg.actors.insert_timeout):
            stats["limiter_blocked"] = True
            stats["busy_seconds"] = 0.0
            stats["version"] = self.version
            return stats
        stats["inserted"] = held  # acknowledged by replay now
        self._pull_weights()
        self.policy.set_progress(env_steps, updates)
        E = self.venv.num_envs
        for _ in range(self.cfg.actors.segment_steps):
            s = self.step
            actions, extras = self._act(explore)
            # the reward that arrived with o_t: none at an episode's first step (base.py convention)
            record = {"obs": s.obs, "action": actions, "reward": np.where(s.first, 0.0, s.reward).astype(np.float32),
                      "first": s.first,
                      "last": np.zeros(E, bool), "terminal": np.zeros(E, bool), **extras}
            self.writer.add(record, version=self.version)
            nxt = self.venv.step(actions)
            self.ep_return += nxt.reward
            self.ep_length += 1
            done = nxt.terminated | nxt.truncated
            if done.any():
                idx = np.flatnonzero(done)
                final = {"obs": nxt.final_obs[idx], "action": np.zeros_like(actions[idx]),
                         "reward": nxt.reward[idx], "first": np.zeros(len(idx), bool),
                         "last": np.ones(len(idx), bool), "terminal": nxt.terminated[idx],
                         **{k: np.zeros_like(v[idx]) for k, v in extras.items()}}
                self.writer.add(final, version=self.version, env_ids=idx)
                stats["episodes"].extend(self.ep_return[idx].tolist())
                stats["lengths"].extend(self.ep_length[idx].tolist())
                self.ep_return[idx] = 0.0
                self.ep_length[idx] = 0
            self.step = nxt
            stats["env_steps"] += E
        batch = self.writer.pop()
        if len(batch):
            self.pending = batch if self.pending is None else self.pending.concat(batch)
        n_pending = 0 if self.pending is None else len(self.pending)
        ok = self._flush(self.cfg.actors.insert_timeout)
        stats["inserted"] += n_pending if ok else 0
        stats["limiter_blocked"] = not ok
        stats["busy_seconds"] = time.monotonic() - t0
        stats["version"] = self.version
        return stats

    def current_version(self) -> int:
        return self.version

    def probe_actions(self, obs: np.ndarray) -> np.ndarray:
        """Greedy actions for given observations (tests: actions follow the weights)."""
        E = obs.shape[0]
        legal = np.ones((E, self.venv.spec.num_actions), bool) if self.venv.spec.discrete else None
        actions, _ = self.policy.act(obs, np.ones(E, bool), legal, None, False)
        return np.asarray(actions)

    def node_id(self) -> str:
        """The Ray node this collector runs on (placement tests)."""
        import ray

        return ray.get_runtime_context().get_node_id()

    def ping(self) -> bool:
        return True


def _incarnation(restarted: bool) -> int:
    """1 for an actor's first life; a fresh number after Ray restarted it (new random stream)."""
    return 2 + int(time.time() * 1000) % 1_000_000 if restarted else 1
