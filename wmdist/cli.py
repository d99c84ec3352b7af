"""The `wmdist` command: train | config | envs | eval | dream | bench | monitor.

Every user error (bad config, unknown env id, missing file) is one line on stderr with
exit status 2; nothing is started before the config has been checked.
"""
from __future__ import annotations

import argparse
import os
import sys
from typing import Sequence

os.environ.setdefault("MUJOCO_GL", "egl")  # dm_control pixels without a display

EXAMPLES = """examples:
  wmdist train configs/muzero_cartpole.yaml
  wmdist train configs/muzero_cartpole.yaml --set actors.num=2 replay.shards=2
  wmdist train --resume runs/muzero_cartpole-20261122-101500
  wmdist config configs/dreamerv3_cartpole.yaml --set learner.batch_size=8
  wmdist envs dmc:cartpole-balance
  wmdist eval runs/muzero_cartpole-20261122-101500 --episodes 20
  wmdist bench mcts --json
"""


class UsageError(Exception):
    """A user mistake: printed as one line, exit status 2."""


def _positive_int(text: str) -> int:
    """argparse type: an int >= 1 (a count of episodes or steps), refused before anything loads."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid int value: {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="wmdist", description="Distributed training of world-model agents "
                                "(MuZero and Dreamer families) on Ray.", epilog=EXAMPLES,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    t = sub.add_parser("train", help="train from a config (embedded local Ray unless --address)",
                       description="Train an agent. The config is checked before anything starts; the run "
                       "directory (runs/<name>-<time>) gets the resolved config, metrics.jsonl, checkpoints and "
                       "learning_curve.png.")
    t.add_argument("config", nargs="?", help="YAML config (see configs/)")
    # extend: every `--set` counts (nargs="+" alone keeps only the last flag's list)
    t.add_argument("--set", action="extend", nargs="+", default=[], metavar="KEY=VALUE",
                   help="dotted overrides, e.g. actors.num=8")
    t.add_argument("--address", default=None, help="join a running Ray cluster ('auto' = the local one)")
    t.add_argument("--resume", default=None, metavar="RUN_DIR", help="continue a run from its latest checkpoint")
    t.add_argument("--local", action="store_true",
                   help="run every role in this process without Ray (ray.local=true): for debugging and smoke runs")

    c = sub.add_parser("config", help="print the resolved config (or every field's doc with --docs)",
                       description="Resolve defaults, overlays and --set overrides, check them, print YAML.")
    c.add_argument("config", nargs="?", help="YAML config")
    c.add_argument("--set", action="extend", nargs="+", default=[], metavar="KEY=VALUE", help="dotted overrides")
    c.add_argument("--docs", action="store_true", help="list every field with its default and doc")

    e = sub.add_parser("envs", help="list env families, or check an env id and print its spec",
                       description="Without an id: the env families and example ids. With one: build it and "
                       "print its EnvSpec (an unknown id is an error naming the closest match).")
    e.add_argument("id", nargs="?", help="e.g. gym:CartPole-v1, dmc:cartpole-balance, atari:Pong, board:tictactoe")
    e.add_argument("--pixels", action="store_true", help="dm_control from 64x64 pixels")

    v = sub.add_parser("eval", help="play greedy (or, with --explore, sampled) episodes with a run's latest checkpoint",
                       description="Greedy episodes with the latest checkpoint of RUN_DIR; prints the returns. "
                       "Board games play the run's opponent: tic-tac-toe's exact solver, connect four's UCT "
                       "search (or you, with --human).")
    v.add_argument("run_dir")
    v.add_argument("--episodes", type=_positive_int, default=10)
    v.add_argument("--simulations", type=_positive_int, default=None,
                   help="MuZero family: search simulations per move (default: the run's eval.num_simulations, "
                        "else its algo.search.num_simulations)")
    v.add_argument("--explore", action="store_true",
                   help="one-player envs: act as the collectors do (sample the policy) instead of greedily; "
                        "DreamerV3's own evaluation samples its actor (the run's eval.explore)")
    v.add_argument("--video", default=None, metavar="PATH.gif", help="record the first episode")
    v.add_argument("--human", action="store_true", help="board games: play against the agent at the terminal")

    d = sub.add_parser("dream", help="open-loop prediction video of a world model that predicts observations",
                       description="Real frames beside the model's: 5 observed steps, then imagined.")
    d.add_argument("run_dir")
    d.add_argument("--out", default=None, help="output GIF (default RUN_DIR/dream.gif)")
    d.add_argument("--horizon", type=_positive_int, default=None,
                   help="imagined steps: of the video (default 45), or the longest horizon --error measures (16)")
    d.add_argument("--check", action="store_true",
                   help="World Models: score the controller and fixed policies in the dream and in the real env, "
                        "side by side (where M is wrong, CMA-ES will exploit it)")
    d.add_argument("--rollouts", type=_positive_int, default=64, help="--check: dream rollouts per policy")
    d.add_argument("--episodes", type=_positive_int, default=5, help="--check: real episodes per policy; "
                                                                       "--error: greedy episodes measured")
    d.add_argument("--error", action="store_true",
                   help="Dreamer, PlaNet: RMS error of the model's open-loop predictions 1, 2, 4 ... --horizon steps "
                        "ahead beside predicting no change, per observation dimension (RUN_DIR/dream_error.json)")

    from wmdist.bench.runner import BENCHES, LONG

    b = sub.add_parser("bench", help=f"run a benchmark ({', '.join(BENCHES)}, all; {', '.join(LONG)} by name)",
                       description="Each measured case prints one JSON object per line with --json.")
    b.add_argument("name")
    b.add_argument("--json", action="store_true", help="one JSON object per line (default: a table)")
    b.add_argument("--quick", action="store_true", help="a small subset of cases")

    m = sub.add_parser("monitor", help="print the commands that launch Prometheus and Grafana beside a run")
    m.add_argument("run_dir")
    return p


def _load(path: str | None, overrides: list[str]):
    from wmdist.config.errors import ConfigError
    from wmdist.config.loader import load_config

    if not path:
        raise ConfigError("a config file is required, e.g. configs/muzero_cartpole.yaml")
    return load_config(path, overrides)


def _train_overrides(a: argparse.Namespace) -> list[str]:
    if a.local and a.address:
        raise UsageError("--local runs without Ray; it cannot join --address")
    return (list(a.set) + ([f"ray.address={a.address}"] if a.address else [])
            + (["ray.local=true"] if a.local else []))


def cmd_train(a: argparse.Namespace) -> int:
    from wmdist.runtime.train import train

    if a.resume:
        if a.config:  # the run directory holds its own config: a second one would be ignored
            raise UsageError(f"give a CONFIG or --resume RUN_DIR, not both (the run's own config is "
                             f"{a.resume}/config.yaml; change it with --set)")
        return train(resume=a.resume, overrides=_train_overrides(a))
    overrides = _train_overrides(a)
    return train(cfg=_load(a.config, overrides))


def cmd_config(a: argparse.Namespace) -> int:
    from wmdist.config.loader import describe, dump_yaml

    if a.docs:
        from wmdist.config.schema import RunConfig

        rows = describe(RunConfig)
        if a.config:
            cfg = _load(a.config, a.set)
            rows = [r for r in rows if not r[0].startswith("algo")] + describe(type(cfg.algo), "algo")
        for key, default, doc in rows:
            print(f"{key:36s} {default:>14s}  {doc}")
        return 0
    print(dump_yaml(_load(a.config, a.set)), end="")
    return 0


def cmd_envs(a: argparse.Namespace) -> int:
    from wmdist.envs.config import EnvConfig
    from wmdist.envs.factory import check_id, list_families
    from wmdist.runtime.train import env_spec_or_error

    if not a.id:
        for family, desc in list_families():
            print(f"{family:8s} {desc}")
        return 0
    check_id(a.id)
    spec = env_spec_or_error(EnvConfig(id=a.id, pixels=a.pixels))
    for k, v in spec.__dict__.items():
        print(f"{k:18s} {v}")
    return 0


def cmd_eval(a: argparse.Namespace) -> int:
    from wmdist.runtime.evaluate import evaluate_run

    return evaluate_run(a.run_dir, episodes=a.episodes, video=a.video, human=a.human, simulations=a.simulations or 0,
                        explore=a.explore)


def cmd_dream(a: argparse.Namespace) -> int:
    from wmdist.config.errors import ConfigError
    from wmdist.runtime.evaluate import dream_run

    if a.check and a.error:
        raise ConfigError("dream: --check and --error are two different reports; ask for one")
    if a.check:
        from wmdist.runtime.evaluate import dream_check_run

        return dream_check_run(a.run_dir, rollouts=a.rollouts, episodes=a.episodes)
    if a.error:
        from wmdist.runtime.dream_error import dream_error_run

        return dream_error_run(a.run_dir, episodes=a.episodes, horizon=a.horizon or 16)
    return dream_run(a.run_dir, out=a.out, horizon=a.horizon or 45)


def cmd_bench(a: argparse.Namespace) -> int:
    from wmdist.bench.runner import run_bench

    return run_bench(a.name, as_json=a.json, quick=a.quick)


def cmd_monitor(a: argparse.Namespace) -> int:
    from pathlib import Path

    from wmdist.telemetry.monitor import monitor_commands

    from wmdist.telemetry.monitor import tensorboard_lines

    run = Path(a.run_dir)
    if not (run / "config.yaml").is_file():
        raise UsageError(f"{a.run_dir} is not a wmdist run directory (no config.yaml)")
    port_file = run / "metrics_port"
    if not port_file.is_file():  # metrics were off: TensorBoard still has every figure
        print("\n".join(tensorboard_lines(run.resolve())))
        print("# Prometheus/Grafana: this run served no metrics (metrics.enabled: false)")
        return 0
    print(monitor_commands(a.run_dir, int(port_file.read_text().strip())))
    return 0


COMMANDS = {"train": cmd_train, "config": cmd_config, "envs": cmd_envs, "eval": cmd_eval,
            "dream": cmd_dream, "bench": cmd_bench, "monitor": cmd_monitor}


def main(argv: Sequence[str] | None = None) -> int:
    from wmdist.config.errors import ConfigError

    args = _parser().parse_args(argv)
    if args.command == "train" and argv is None:
        from wmdist.runtime import own_session

        if own_session.wanted():  # the driver in a session of its own: see own_session.py
            return own_session.run_relayed(own_session.wmdist_command(sys.argv[1:]))
    try:
        return COMMANDS[args.command](args)
    except (ConfigError, UsageError, FileNotFoundError) as err:
        print(f"wmdist: error: {err}", file=sys.stderr)
        return 2
    except ValueError as err:  # bad ids and inputs raised as ValueError by the packages
        msg = str(err).strip().splitlines()
        print(f"wmdist: error: {msg[0] if msg else type(err).__name__}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("wmdist: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

