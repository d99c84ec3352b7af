"""`wmdist train`: check everything that can be checked, then start Ray and the topology and
run the driver loop.

Exit status: 0 when the run ends on its budget or target, 2 for bad input (one line, before
anything starts or is written), 130 after Ctrl-C (143 after SIGTERM) with a final checkpoint,
1 for a failure after start-up: one line that says how to resume, the traceback in the run
directory's `wmdist.log`.
"""
from __future__ import annotations

import logging
import signal
import sys
import time
from pathlib import Path

from wmdist.config.errors import ConfigError
from wmdist.config.loader import config_from_tree, dump_yaml
from wmdist.config.schema import RunConfig
from wmdist.envs.config import EnvConfig

CONFIG_FILE = "config.yaml"
METRICS_FILE = "metrics.jsonl"
CURVE_FILE = "learning_curve.png"
LOG_FILE = "wmdist.log"

log = logging.getLogger("wmdist")


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
    from wmdist.config.loader import apply_overrides, read_yaml_mapping

    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise ConfigError(f"{run_dir} is not a wmdist run directory (no {CONFIG_FILE})")
    tree = read_yaml_mapping(path)  # a damaged config.yaml is one line, like any config file
    return config_from_tree(apply_overrides(tree, list(overrides or [])), default_name=Path(run_dir).name)


def env_spec_or_error(cfg: RunConfig | EnvConfig):
    """The env's spec (it is built once to read it); any failure is one ConfigError line."""
    from wmdist.envs.factory import env_spec

    try:
        return env_spec(cfg.env if isinstance(cfg, RunConfig) else cfg)
    except Exception as err:  # a constructor that raises anything is a bad env config, not a crash
        lines = str(err).strip().splitlines()
        raise ConfigError(f"env.id: {lines[0] if lines else type(err).__name__}") from None


_SIGTERM_SEEN = False  # the interrupt came from SIGTERM (exit 143), not Ctrl-C (exit 130)


def _stop_on_sigterm() -> None:
    """SIGTERM stops the run like Ctrl-C: drain, checkpoint, shut the actors down. Background
    shell jobs ignore SIGINT, so this is the signal that reaches them."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return

    def interrupt(_signum, _frame):
        global _SIGTERM_SEEN
        _SIGTERM_SEEN = True
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)


def _file_log(run_dir: Path) -> logging.Handler:
    """Tracebacks and service events go to RUN_DIR/wmdist.log, never to the console."""
    handler = logging.FileHandler(run_dir / LOG_FILE, encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    log.propagate = False
    return handler


def _resume_hint(run_dir: Path) -> str:
    from wmdist.runtime import checkpoint as ck

    if ck.latest_checkpoint(run_dir) is not None:
        return f"resume with `wmdist train --resume {run_dir}`"
    return f"nothing was checkpointed yet: start again with `wmdist train {run_dir / CONFIG_FILE}`"


def _prepare(cfg: RunConfig | None, resume: str | None, overrides: list[str] | None):
    """Every check that can run before Ray starts (`preflight.py`); creates nothing on failure
    except the exporter's socket, which the caller closes."""
    from wmdist.runtime import checkpoint as ck
    from wmdist.runtime import preflight as pf
    from wmdist.runtime.preflight_memory import check_memory
    from wmdist.runtime.preflight_model import check_model

    ckpt, state = None, None
    if resume:
        run_dir = Path(resume)
        if not run_dir.is_dir():
            raise ConfigError(f"--resume {resume}: no such run directory")
        cfg = load_run_config(run_dir, overrides)
        ckpt = ck.latest_checkpoint(run_dir)
        if ckpt is None:
            raise ConfigError(f"{run_dir} has no checkpoint to resume from")
    assert cfg is not None
    spec, algo = pf.check_env_and_algo(cfg)
    fields = algo.step_fields()
    check_memory(cfg, fields)
    check_model(cfg, algo)  # before a resume builds the learner for real
    if ckpt is not None:
        state = pf.check_checkpoint(Path(resume), ckpt, cfg, algo)
        pf.check_replay_checkpoint(ckpt, cfg, fields)
    del algo
    pf.check_resources(cfg)
    pf.check_ray_address(cfg)
    pf.check_replay_store(cfg)
    hub = pf.start_metrics(cfg)
    return cfg, spec, fields, ckpt, state, hub


def train(cfg: RunConfig | None = None, resume: str | None = None, overrides: list[str] | None = None,
          out=sys.stdout) -> int:
    """Run training; returns the process exit status."""
    from wmdist.runtime import checkpoint as ck
    from wmdist.runtime import preflight as pf
    from wmdist.runtime.run_lock import RunLock

    # a run directory another driver is using is refused before its files are read
    lock = RunLock(resume).acquire() if resume and Path(resume).is_dir() else None
    try:
        cfg, spec, fields, ckpt, state, hub = _prepare(cfg, resume, overrides)
        try:
            run_dir = Path(resume) if resume else pf.make_run_dir(cfg)
            lock = lock or RunLock(run_dir).acquire()
        except BaseException:
            if hub is not None:
                hub.close()
            raise
        # a resume rewrites config.yaml only now, after its checkpoint loaded into this config's model
        (run_dir / CONFIG_FILE).write_text(dump_yaml(cfg))
        ck.clean_partial(run_dir)
        handler = _file_log(run_dir)
        log.info("start%s: %s", f" (resume from {ckpt.name})" if ckpt else "", " ".join(sys.argv))
        print(f"wmdist: run directory {run_dir}", file=out, flush=True)
        _compile_note(cfg, out)
        try:
            return _run(cfg, spec, fields, run_dir, ckpt, state, hub, out)
        finally:
            log.removeHandler(handler)
            handler.close()
    finally:
        if lock is not None:
            lock.release()


def _compile_note(cfg: RunConfig, out) -> None:
    """Says why a learner with compiled phases makes no update for its first minutes."""
    names = {"world_model": "world-model", "actor_critic": "actor-critic"}
    phases = [name for key, name in names.items() if getattr(cfg.algo, f"compile_{key}", False)]
    if phases:
        print(f"wmdist: the learner compiles its {' and '.join(phases)} phase{'s' if len(phases) > 1 else ''} in its "
              "first updates: minutes on a first start, less from inductor's cache; env steps wait meanwhile",
              file=out, flush=True)


def _run(cfg: RunConfig, spec, fields: dict, run_dir: Path, ckpt: Path | None, state: dict | None, hub,
         out) -> int:
    """Start Ray and the roles, run the driver; every failure here is one line plus the log."""
    from wmdist.runtime import checkpoint as ck
    from wmdist.telemetry.curves import plot_learning_curve
    from wmdist.runtime.driver import Counters, Driver
    from wmdist.runtime.faults import root_cause
    from wmdist.telemetry.publish import Telemetry
    from wmdist.runtime.topology import build, start_ray

    topo, telemetry, driver = None, None, None
    phase = "starting Ray"
    try:
        if cfg.ray.local:
            log.info("local runner: every role in this process, no Ray")
        else:
            start_ray(cfg)
        _stop_on_sigterm()  # after Ray, whose driver installs a SIGTERM handler of its own that aborts
        phase = "starting the actors"
        topo = build(cfg, spec, run_dir, fields, local=cfg.ray.local)
        counters = Counters()
        if ckpt is not None:
            from wmdist.runtime.calls import get

            phase = f"restoring {ckpt.name}"
            counters = Counters.from_dict(ck.load_counters(ckpt))
            get(topo.learner.load.remote(state))
            if (ckpt / "replay").exists():
                topo.replay.restore(str(ckpt / "replay"))
            print(f"wmdist: resumed from {ckpt.name} at {counters.env_steps} env steps, {counters.updates} updates",
                  file=out, flush=True)
        state = None  # the learner holds it now
        telemetry = Telemetry(cfg, run_dir, out, hub=hub)
        hub = None
        tel = telemetry

        def plot() -> None:
            plot_learning_curve(str(run_dir / METRICS_FILE), str(run_dir / CURVE_FILE))
            tel.curve(run_dir / CURVE_FILE, driver.c.env_steps)

        driver = Driver(topo, counters, on_tick=telemetry.update, log_path=run_dir / METRICS_FILE, plot=plot,
                        on_record=telemetry.record)
        phase = "training"
        result = driver.run()
    except KeyboardInterrupt:  # during start-up (the driver loop handles its own)
        log.info("interrupted while %s", phase)
        print(f"wmdist: interrupted while {phase}; {_resume_hint(run_dir)}", file=sys.stderr, flush=True)
        return 143 if _SIGTERM_SEEN else 130
    except Exception as err:  # noqa: BLE001 - one line on the console, the traceback in the log
        log.exception("failed while %s", phase)
        print(f"wmdist: error while {phase}: {root_cause(err)}; the traceback is in {run_dir / LOG_FILE}; "
              f"{_resume_hint(run_dir)}", file=sys.stderr, flush=True)
        return 1
    finally:
        _close(hub, telemetry, topo)
    return _report(result, driver, run_dir, out)


def _close(hub, telemetry, topo) -> None:
    """Shut everything down; a second Ctrl-C here must not leave services behind."""
    for step in (lambda: hub.close() if hub is not None else None,
                 lambda: telemetry.close() if telemetry is not None else None,
                 lambda: topo.shutdown() if topo is not None else None):
        try:
            step()
        except BaseException:  # noqa: BLE001 - keep closing the rest
            log.exception("shutdown step failed")


def _report(result, driver, run_dir: Path, out) -> int:
    """The run's last lines and its exit status."""
    snap = driver.last_snapshot
    ret = snap.get("train_return")
    summary = (f"wmdist: {result.status} ({result.message}) after {result.counters.env_steps} env steps, "
               f"{result.counters.updates} updates, {driver.elapsed():.0f}s"
               + (f"; mean train return {ret:.1f}" if ret is not None else "")
               + (f"; eval return {driver.eval_return:.1f}" if driver.eval_return is not None else ""))
    print(summary, file=out, flush=True)
    log.info("%s", summary)
    if driver.checkpoint_error is not None and result.status != "learner_failed":
        print(f"wmdist: error: the final checkpoint could not be written ({driver.checkpoint_error}); the "
              f"traceback is in {run_dir / LOG_FILE}; {_resume_hint(run_dir)} (from the last good checkpoint)",
              file=sys.stderr, flush=True)
        return 1
    if result.status in ("learner_failed", "error", "nan_stop"):
        print(f"wmdist: error: {result.message}; {_resume_hint(run_dir)}", file=sys.stderr, flush=True)
        return 1
    if result.status == "interrupted":
        print(f"wmdist: checkpoint written; {_resume_hint(run_dir)}", file=out, flush=True)
        return 143 if _SIGTERM_SEEN else 130
    print(f"wmdist: curve {run_dir / CURVE_FILE}; {_resume_hint(run_dir)}", file=out)
    return 0
