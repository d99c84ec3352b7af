"""The run configuration: one typed section per part of the system.

Sections owned by a package are declared there (`EnvConfig` in `wmdist/envs/config.py`,
`ReplayConfig` in `wmdist/replay/config.py`, each algorithm's `Config` in its folder); the
runtime's own sections are declared here. Every field documents itself through `param`.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from wmdist.config.fields import MAX_PER_DECISION, param, section
from wmdist.envs.config import EnvConfig
from wmdist.replay.config import ReplayConfig


@dataclass
class RunSection:
    name: str = param("", "run name; the run directory is <dir>/<name> ('' = <config name>-<time>)")
    dir: str = param("runs", "parent folder of run directories")
    seed: int = param(0, "seed for envs, networks and search", ge=0, le=2**32 - 1)  # numpy's and gymnasium's range
    max_env_steps: int = param(50_000, "stop after this many env steps (0 = no limit)", ge=0)
    max_updates: int = param(0, "stop after this many learner updates (0 = no limit)", ge=0)
    max_minutes: float = param(30.0, "stop after this much wall time (0 = no limit)", ge=0)
    stop_at_eval_return: float | None = param(None, "stop once a greedy evaluation's mean return reaches this (null = never)")
    stop_at_lost_lines: int | None = param(
        None, "tic-tac-toe: stop once the evaluator's whole-tree judge finds at most this many lost lines; the final "
        "checkpoint then plays the judged weights, not the learner's later ones (null = never)", ge=0)
    log_every_seconds: float = param(2.0, "how often the driver gathers metrics, logs and prints progress", gt=0)
    plot_every_seconds: float = param(30.0, "how often the learning-curve PNG is redrawn", gt=0)


@dataclass
class ActorsConfig:
    num: int = param(1, "number of collector actors", ge=1, le=4096)
    envs_per_actor: int = param(8, "envs stepped together (batched inference) in each collector", ge=1, le=4096)
    cpus: float = param(0.5, "Ray CPUs per collector (torch threads = max(1, floor(cpus)))", gt=0)
    gpus: float = param(0.0, "Ray GPUs per collector", ge=0)
    resources: dict = param({}, "custom Ray resources per collector, e.g. {collector: 1} to place on tagged nodes")
    segment_steps: int = param(50, "env steps per segment: weights are pulled and sequences flushed between segments", ge=1)
    max_restarts: int = param(-1, "Ray restarts of a collector that dies (-1 = unlimited)", ge=-1)
    insert_timeout: float = param(5.0, "seconds a collector waits for the rate limiter before retrying", gt=0)
    warmup_random_steps: int = param(0, "env steps (per collector) taken with uniform random actions first", ge=0)


@dataclass
class LearnerConfig:
    batch_size: int = param(128, "sequences per update", ge=1)
    cpus: float = param(1.0, "Ray CPUs for the learner (torch threads = max(1, floor(cpus)))", gt=0)
    gpus: float = param(0.0, "Ray GPUs for the learner (> 0 puts it on CUDA)", ge=0)
    resources: dict = param({}, "custom Ray resources for the learner")
    publish_every: int = param(10, "publish a weight snapshot every K updates", ge=1)
    prefetch: int = param(2, "batches sampled ahead in a background thread", ge=1, le=16)
    max_nan_streak: int = param(20, "stop after this many non-finite updates in a row", ge=1)
    sample_timeout: float = param(1.0, "seconds one sample call may wait on the limiter before re-checking for stop", gt=0)
    max_restarts: int = param(
        3, "times a learner whose process died (killed, out of memory, crashed) is started again in the same run "
           "from the latest checkpoint (or afresh before the first), losing only the updates since; replay, "
           "collectors and counters go on. 0 = the run stops with the resume command instead", ge=0)


@dataclass
class ReanalyzeConfig:
    num: int = param(0, "reanalyzer actors (0 = none)", ge=0)
    cpus: float = param(0.5, "Ray CPUs per reanalyzer", gt=0)
    gpus: float = param(0.0, "Ray GPUs per reanalyzer", ge=0)
    resources: dict = param({}, "custom Ray resources per reanalyzer")
    batch_size: int = param(32, "sequences per reanalyze job", ge=1)
    fraction: float = param(0.8, "target share of learner samples carrying fresh targets (Reanalyze paper: 0.8)", ge=0, le=1)
    nice: int = param(0, "OS nice level added to the reanalyzers' (0 = as the other roles): above 0 they use the CPU the "
                         "learner and collectors leave idle instead of an equal share of it, so a busy reanalyzer no "
                         "longer slows the learner that paces the run (wmdist/runtime/priority.py)", ge=0, le=19)


@dataclass
class EvalConfig:
    every_seconds: float = param(60.0, "seconds between evaluations (0 = not by time)", ge=0)
    every_env_steps: int = param(0, "also evaluate each time this many more env steps were taken "
                                    "(0 = not by steps), so a run that learns in 3k steps is seen doing so; "
                                    "with both 0 there is no evaluator", ge=0)
    episodes: int = param(10, "greedy episodes per evaluation", ge=1)
    explore: bool = param(False, "act as the collectors do instead of greedily: sample the policy (DreamerV3's own "
                                 "evaluation samples its actor), with the algorithm's exploration noise or visit "
                                 "temperature where it has them; one-player envs only")
    envs: int = param(5, "envs the evaluator steps together", ge=1, le=4096)
    cpus: float = param(0.25, "Ray CPUs for the evaluator", gt=0)
    opponent_rollouts: int = param(200, "board:connect4: random rollouts per move of the MCTS (UCT) opponent", ge=1)
    num_simulations: int = param(0, "MuZero family: search simulations per evaluation move (0 = algo.search's own); "
                                    "more search at test time than in self-play", ge=0, le=MAX_PER_DECISION)
    judge_lines: bool = param(True, "board:tictactoe: also play the greedy agent against every opponent line and "
                                    "log the lines it loses (eval_lost_lines)")
    gpus: float = param(0.0, "Ray GPUs for the evaluator", ge=0)
    resources: dict = param({}, "custom Ray resources for the evaluator")

    @property
    def enabled(self) -> bool:
        return self.every_seconds > 0 or self.every_env_steps > 0


@dataclass
class MetricsConfig:
    enabled: bool = param(True, "serve Prometheus metrics from the driver")
    host: str = param("127.0.0.1", "exporter bind address (0.0.0.0 only if you mean it)")
    port: int = param(0, "exporter port (0 = a free port; printed at start)", ge=0, le=65535)
    tensorboard: bool = param(True, "also write TensorBoard event files (RUN_DIR/tensorboard): every metrics.jsonl "
                                    "scalar and the learning curve; `wmdist monitor RUN_DIR` says how to open them")


@dataclass
class CheckpointConfig:
    every_seconds: float = param(120.0, "seconds between checkpoints (0 = only at the end)", ge=0)
    keep: int = param(2, "checkpoints kept", ge=1)
    replay: bool = param(True, "include the replay contents (memory backend) in checkpoints")


@dataclass
class RayConfig:
    address: str = param("", "Ray cluster to join ('' = start an embedded local instance; 'auto' = the running one)")
    local: bool = param(False, "run every role in this one process without Ray (the local runner, "
                               "`wmdist train --local`): same code, one at a time, a debugger can step through it")
    num_cpus: int = param(0, "CPUs of the embedded instance (0 = all of this machine)", ge=0)
    num_gpus: int = param(-1, "GPUs of the embedded instance (-1 = detect)", ge=-1)
    object_store_mb: int = param(512, "object store size of the embedded instance in MB", ge=64)
    worker_niceness: int = param(0, "nice level of the embedded instance's workers (Ray's default, 15, lets any other "
                                    "process on the machine pre-empt the learner)", ge=0, le=19)


@dataclass
class RunConfig:
    run: RunSection = section(RunSection, "run identity, budget and logging")
    env: EnvConfig = section(EnvConfig, "environment (see `wmdist envs`)")
    algo: Any = param(None, "algorithm: `name` plus that algorithm's fields")
    actors: ActorsConfig = section(ActorsConfig, "collector actors")
    replay: ReplayConfig = section(ReplayConfig, "replay service")
    learner: LearnerConfig = section(LearnerConfig, "the learner")
    reanalyze: ReanalyzeConfig = section(ReanalyzeConfig, "reanalyzer actors")
    eval: EvalConfig = section(EvalConfig, "the evaluator")
    metrics: MetricsConfig = section(MetricsConfig, "Prometheus exporter")
    checkpoint: CheckpointConfig = section(CheckpointConfig, "checkpoints")
    ray: RayConfig = section(RayConfig, "Ray cluster")
    algo_name: str = param("", "resolved from algo.name (set by the loader)")
