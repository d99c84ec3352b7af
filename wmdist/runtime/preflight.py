"""Every check `wmdist train` can make before Ray starts or a run directory exists.

Each failure is one `ConfigError` line (exit status 2) and leaves nothing behind: the env
builds, the algorithm builds, the roles fit the embedded instance, a cluster to join answers
at ray.address, the replay store is reachable with its password, the metrics port is free (it
is bound here, and kept), the run directory can be created, and a checkpoint to resume loads
into the model the config describes, its replay files included.
"""
from __future__ import annotations

import os
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from wmdist.config.errors import ConfigError, first_line, mismatch_line
from wmdist.config.schema import RunConfig
from wmdist.envs.spec import EnvSpec
from wmdist.runtime.preflight_memory import node_memory_bytes

REDIS_CHECK_TIMEOUT = 3.0  # seconds to reach an external redis before calling it unreachable


@dataclass
class Checked:
    """What the checks built and the run keeps using."""

    spec: EnvSpec
    fields: dict
    hub: Any = None  # a started MetricsHub, or None when metrics are off


def check_env_and_algo(cfg: RunConfig) -> tuple[EnvSpec, Any]:
    from wmdist.algos.base import PACKED_WINDOWS
    from wmdist.runtime.roles.setup import build_algorithm
    from wmdist.runtime.train import env_spec_or_error

    spec = env_spec_or_error(cfg)
    if cfg.run.stop_at_lost_lines is not None and cfg.env.id != "board:tictactoe":  # evaluator off: never fires
        raise ConfigError(f"run.stop_at_lost_lines needs the evaluator's whole-tree judge, which only "
                          f"board:tictactoe has (env.id is {cfg.env.id})")
    try:
        algo = build_algorithm(cfg, spec, cfg.run.seed)
        algo.check_run(cfg)
    except (ValueError, TypeError) as err:
        raise ConfigError(first_line(err)) from None
    if cfg.replay.pack_episodes and not algo.offers(PACKED_WINDOWS):
        raise ConfigError(f"replay.pack_episodes: {cfg.algo_name}'s learner reads each window as one episode "
                          f"(its targets would run across episodes); only learners that restart at `first` "
                          f"inside a window can pack them (dreamer)")
    return spec, algo


def check_resources(cfg: RunConfig) -> None:
    """An embedded instance's size is known before it starts: check the roles fit it now."""
    from wmdist.runtime.resources import check_fits

    if cfg.ray.local:
        if cfg.ray.address:
            raise ConfigError("ray.local runs without Ray; it cannot join ray.address")
        return  # no Ray: every role shares this process
    if cfg.ray.address:
        return  # a cluster's size is known only once joined (checked in topology.build)
    detected = _detected_gpus()
    if cfg.ray.num_gpus > detected:
        # Ray would schedule GPU roles on devices that do not exist; they would then run on the CPU
        raise ConfigError(f"ray.num_gpus={cfg.ray.num_gpus}, but torch sees {detected} CUDA device(s) on this "
                          f"machine; leave ray.num_gpus at -1 to detect them")
    memory = node_memory_bytes()
    if memory and cfg.ray.object_store_mb * 2**20 > memory:
        raise ConfigError(f"ray.object_store_mb={cfg.ray.object_store_mb} is more than this machine's memory "
                          f"({memory / 2**20:,.0f} MB); the object store lives in it")
    gpus = cfg.ray.num_gpus if cfg.ray.num_gpus >= 0 else detected
    cluster = {"CPU": float(cfg.ray.num_cpus or os.cpu_count() or 1), "GPU": float(gpus)}
    check_fits(cfg, cluster)


RAY_CHECK_TIMEOUT = 3.0  # seconds for a cluster's head to accept a TCP connection


def check_ray_address(cfg: RunConfig) -> None:
    """A HOST:PORT (or ray://HOST:PORT) to join must accept a connection before anything is created:
    a typo or a head that is down is bad input, not a failed run. 'auto' is left to Ray."""
    import socket

    address = cfg.ray.address
    if not address or address == "auto" or cfg.ray.local:
        return
    hostport = address.split("://", 1)[1] if "://" in address else address
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise ConfigError(f"ray.address {address!r}: expected 'auto', HOST:PORT or ray://HOST:PORT "
                          f"(the head's GCS port, 6379 by default)")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=RAY_CHECK_TIMEOUT):
            pass
    except OSError as err:
        raise ConfigError(f"ray.address {address}: nothing answers there ({err.strerror or err}); start the "
                          f"head with `ray start --head`, or leave ray.address empty for a local instance") from None


def _detected_gpus() -> int:
    import torch

    return torch.cuda.device_count() if torch.cuda.is_available() else 0


def check_replay_store(cfg: RunConfig) -> None:
    """redis: the private server can be started, or the external one answers our password."""
    r = cfg.replay
    if r.backend != "redis":
        return
    if not r.redis_url:
        if shutil.which("redis-server") is None:
            raise ConfigError("replay.backend=redis needs redis-server (apt-get install redis-server, "
                              "or `make system-deps`)")
        return
    import redis

    from wmdist.replay.storage_redis import connect

    if r.redis_password_file and not os.path.isfile(r.redis_password_file):
        raise ConfigError(f"replay.redis_password_file: no such file {r.redis_password_file!r}")
    try:
        client = connect(r.redis_url, r.redis_password_file)
    except ValueError as err:  # scheme or URL syntax
        raise ConfigError(first_line(err)) from None
    except OSError as err:
        raise ConfigError(f"replay.redis_password_file {r.redis_password_file!r}: {err.strerror}") from None
    client.connection_pool.connection_kwargs.update(socket_timeout=REDIS_CHECK_TIMEOUT,
                                                    socket_connect_timeout=REDIS_CHECK_TIMEOUT)
    try:
        client.ping()
    except (redis.AuthenticationError, redis.ResponseError) as err:
        if not isinstance(err, redis.AuthenticationError) and "AUTH" not in str(err).upper():
            raise ConfigError(f"replay.redis_url {r.redis_url}: {first_line(err)}") from None
        if client.connection_pool.connection_kwargs.get("password") is None:
            raise ConfigError(f"replay.redis_url {r.redis_url}: the server wants a password "
                              f"(set replay.redis_password_file)") from None
        raise ConfigError(f"replay.redis_url {r.redis_url}: the password was refused "
                          f"(check replay.redis_password_file)") from None
    except (redis.ConnectionError, redis.TimeoutError) as err:
        raise ConfigError(f"replay.redis_url {r.redis_url}: nothing answers there ({first_line(err)})") from None
    finally:
        client.close()


def start_metrics(cfg: RunConfig):
    """Bind the exporter now, so a busy port fails before anything starts (kept for the run)."""
    if not cfg.metrics.enabled:
        return None
    from wmdist.telemetry.metrics import MetricsHub

    hub = MetricsHub(host=cfg.metrics.host, port=cfg.metrics.port)
    try:
        hub.start()
    except OSError as err:
        raise ConfigError(f"metrics.port {cfg.metrics.port} on {cfg.metrics.host} cannot be used "
                          f"({err.strerror or err}); pick another port, or 0 for a free one") from None
    return hub


def make_run_dir(cfg: RunConfig) -> Path:
    from wmdist.runtime.train import new_run_dir

    try:
        return new_run_dir(cfg)
    except OSError as err:
        raise ConfigError(f"run.dir {cfg.run.dir!r}: cannot create the run directory "
                          f"({err.strerror or err})") from None


def check_checkpoint(run_dir: Path, ckpt: Path, cfg: RunConfig, algo: Any) -> dict:
    """The checkpoint's learner state, loaded into a learner built from `cfg` (so a checkpoint
    of another algorithm, or overrides that change the model's shape, fail here in one line)."""
    from wmdist.runtime import checkpoint as ck
    from wmdist.runtime.train import load_run_config

    saved = load_run_config(run_dir)
    if saved.algo_name != cfg.algo_name:
        raise ConfigError(f"{ckpt} was trained by {saved.algo_name!r}; algo.name={cfg.algo_name!r} cannot resume it")
    try:
        state = ck.load_learner_state(ckpt)
        ck.load_counters(ckpt)
    except Exception as err:  # noqa: BLE001 - unreadable or crafted files: one line
        raise ConfigError(ck.unreadable_message(ckpt, err)) from None
    try:
        algo.make_learner("cpu").load_state_dict(state["learner"])
    except Exception as err:  # noqa: BLE001 - size mismatch, missing keys, another algorithm
        raise ConfigError(f"{ckpt} does not fit the model this config builds ({mismatch_line(err)}); "
                          f"overrides that change the model's shape cannot resume a run") from None
    return state


def check_replay_checkpoint(ckpt: Path, cfg: RunConfig, fields: dict) -> None:
    """The checkpoint's replay files open (never unpickled) and fit the shards `cfg` builds, so a
    truncated file or a changed `replay.shards` / `capacity_steps` / `seq_len` fails here in one
    line instead of after Ray has started. Reads only each file's index and scalars."""
    import json

    from wmdist.replay.shard import saved_layout
    from wmdist.runtime import checkpoint as ck
    from wmdist.runtime.replay_client import shard_capacity

    folder = ckpt / "replay"
    if not folder.exists():
        return
    saved = sorted(folder.glob("shard*.npz"))
    try:
        state = json.loads((folder / "limiter.json").read_text(encoding="utf-8"))
        if not isinstance(state, dict):
            raise ValueError("limiter.json is not a limiter state")
        shapes = [saved_layout(path) for path in saved]
    except Exception as err:  # noqa: BLE001 - truncated, hand-edited or crafted files: one line
        raise ConfigError(ck.unreadable_message(ckpt, err)) from None
    if len(saved) != cfg.replay.shards:
        raise ConfigError(f"{ckpt} holds {len(saved)} replay shard(s), this config builds replay.shards="
                          f"{cfg.replay.shards}; resume with the run's own shard count")
    want = (shard_capacity(cfg.replay, fields), cfg.replay.seq_len)
    for path, have in zip(saved, shapes):
        if have != want:
            raise ConfigError(f"{path} holds {have[0]} sequence slots of length {have[1]}, this config builds "
                              f"{want[0]} of length {want[1]}; replay.capacity_steps and replay.seq_len "
                              f"cannot change on resume")
