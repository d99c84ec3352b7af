"""`wmdist train`: resolve the config, start Ray and the topology, run the driver loop."""
from __future__ import annotations

import sys
import time
from pathlib import Path

import yaml

from wmdist.config.errors import ConfigError
from wmdist.config.loader import config_from_tree, dump_yaml
from wmdist.config.schema import RunConfig

CONFIG_FILE = "config.yaml"
METRICS_FILE = "metrics.jsonl"
CURVE_FILE = "learning_curve.png"


def new_run_dir(cfg: RunConfig) -> Path:
    stamp = time.strftime("%Y%m%d-%H%M%S")
    base = Path(cfg.run.dir) / f"{cfg.run.name}-{stamp}"
    path, n = base, 1
    while path.exists():
        n += 1
        path = Path(f"{base}-{n}")
    path.mkdir(parents=True)
    return path


def load_run_config(run_dir: str | Path, overrides: list[str] | None = None) -> RunConfig:
    """The resolved config saved in a run directory (plus optional overrides)."""
    from wmdist.config.loader import apply_overrides

    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise ConfigError(f"{run_dir} is not a wmdist run directory (no {CONFIG_FILE})")
    tree = yaml.safe_load(path.read_text()) or {}
    return config_from_tree(apply_overrides(tree, list(overrides or [])), default_name=Path(run_dir).name)


def env_spec_or_error(cfg: RunConfig):
    from wmdist.envs.factory import env_spec

    try:
        return env_spec(cfg.env)
    except ValueError as err:
        raise ConfigError(f"env.id: {err}") from None


def _stop_on_sigterm() -> None:
    """SIGTERM (docker stop, kill, a batch scheduler) stops the run like Ctrl-C: drain,
    checkpoint, shut the actors down. Background shell jobs ignore SIGINT, so this is the
    signal that reaches them."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return

    def interrupt(_signum, _frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)


def train(cfg: RunConfig | None = None, resume: str | None = None, overrides: list[str] | None = None,
          out=sys.stdout) -> int:
    """Run training; returns the process exit status."""
    from wmdist.runtime import checkpoint as ck
    from wmdist.runtime.curves import plot_learning_curve
    from wmdist.runtime.driver import Counters, Driver
    from wmdist.runtime.roles import build_algorithm
    from wmdist.runtime.telemetry import Telemetry
    from wmdist.runtime.topology import build, start_ray

    if resume:
        run_dir = Path(resume)
        cfg = load_run_config(run_dir, overrides)
        ckpt = ck.latest_checkpoint(run_dir)
        if ckpt is None:
            raise ConfigError(f"{run_dir} has no checkpoint to resume from")
    else:
        assert cfg is not None
        ckpt = None
    spec = env_spec_or_error(cfg)
    fields = build_algorithm(cfg, spec, cfg.run.seed).step_fields()
    if not resume:
        run_dir = new_run_dir(cfg)
    (run_dir / CONFIG_FILE).write_text(dump_yaml(cfg))
    print(f"wmdist: run directory {run_dir}", file=out, flush=True)

    start_ray(cfg)
    topo = build(cfg, spec, run_dir, fields)
    counters = Counters()
    if ckpt is not None:
        import ray

        counters = Counters.from_dict(ck.load_counters(ckpt))
        ray.get(topo.learner.load.remote(ck.load_learner_state(ckpt)))
        if (ckpt / "replay").exists():
            topo.replay.restore(str(ckpt / "replay"))
        print(f"wmdist: resumed from {ckpt.name} at {counters.env_steps} env steps, {counters.updates} updates",
              file=out, flush=True)
    telemetry = Telemetry(cfg, run_dir, out)
    driver = Driver(topo, counters, on_tick=telemetry.update, log_path=run_dir / METRICS_FILE,
                    plot=lambda: plot_learning_curve(str(run_dir / METRICS_FILE), str(run_dir / CURVE_FILE)))
    _stop_on_sigterm()
    try:
        result = driver.run()
    finally:
        telemetry.close()
        topo.shutdown()
    snap = driver.last_snapshot
    ret = snap.get("train_return")
    summary = (f"wmdist: {result.status} ({result.message}) after {result.counters.env_steps} env steps, "
               f"{result.counters.updates} updates, {driver.elapsed():.0f}s"
               + (f"; mean train return {ret:.1f}" if ret is not None else "")
               + (f"; eval return {driver.eval_return:.1f}" if driver.eval_return is not None else ""))
    print(summary, file=out, flush=True)
    if result.status in ("learner_failed", "error", "nan_stop"):
        print(f"wmdist: error: {result.message}; resume with `wmdist train --resume {run_dir}`", file=sys.stderr)
        return 1
    print(f"wmdist: curve {run_dir / CURVE_FILE}; resume with `wmdist train --resume {run_dir}`", file=out)
    return 0
