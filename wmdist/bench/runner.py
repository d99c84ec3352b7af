"""`wmdist bench NAME`: run a benchmark module and print one JSON object per measured case."""
from __future__ import annotations

import importlib
import json
import sys
from typing import IO

from wmdist.config.errors import ConfigError, closest

BENCHES = ("mcts", "replay", "selfplay", "dreamer", "envs", "planner", "cmaes", "goal_planner", "reanalyze",
           "subnormals")
LONG = ("soak", "compile")  # run by name only: not part of `all` (minutes each)


def run_bench(name: str, as_json: bool = False, quick: bool = False, out: IO[str] = sys.stdout) -> int:
    names = BENCHES if name == "all" else (name,)
    for n in names:
        if n not in BENCHES + LONG:
            known = BENCHES + LONG
            raise ConfigError(f"unknown benchmark {n!r}{closest(n, known)}; known: {', '.join(known)}, all")
        module = importlib.import_module(f"wmdist.bench.{n}")
        for case in module.run(quick=quick):
            case = {"bench": n, **case}
            if as_json:
                print(json.dumps(case), file=out, flush=True)
            else:
                print("  ".join(f"{k}={_fmt(v)}" for k, v in case.items()), file=out, flush=True)
    return 0


def _fmt(v: object) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)
