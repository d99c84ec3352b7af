"""Run outputs: metrics as JSONL (one record per report) and the learning-curve PNG.

A record is a flat JSON object (see the two spellings below). The plot reads the file as
it is while training appends to it: a torn last line or a non-JSON line is skipped,
missing keys just leave gaps.
"""
from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any, Iterator, Mapping

# A bare Figure renders through Agg with no display and no pyplot global state
# (safe from a background thread of the driver).
from matplotlib.figure import Figure

from wmdist.telemetry.metrics import snapshot_key

# A record comes in one of two spellings; both are read:
#  - the driver's log line: {"env_steps", "updates", "kind": "train"|"eval", "train_return",
#    "eval_return", "loss/<name>", ...} (eval returns only on kind == "eval" lines);
#  - a `MetricsHub.snapshot()`: {"wmdist_env_steps_total", "wmdist_episode_return{role=eval}",
#    "wmdist_episodes_total{role=eval}", "wmdist_learner_loss{name=<name>}", ...}.
HUB_STEPS = "wmdist_env_steps_total"
HUB_UPDATES = "wmdist_learner_updates_total"
HUB_LOSS_PREFIX = "wmdist_learner_loss{name="
LOG_LOSS_PREFIX = "loss/"


def _jsonable(v: Any) -> Any:
    """Strict JSON: non-finite floats become null (NaN/inf are not JSON)."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if hasattr(v, "tolist") and callable(v.tolist):  # numpy scalars and arrays
        return _jsonable(v.tolist())
    return v


def write_jsonl(path: str | os.PathLike[str], record: Mapping[str, Any]) -> None:
    """Append one record as a single JSON line (written with one call, then flushed)."""
    if not isinstance(record, Mapping):
        raise ValueError(f"write_jsonl: record must be a dict, got {type(record).__name__}")
    line = json.dumps(_jsonable(dict(record)), separators=(",", ":"), allow_nan=False) + "\n"
    with open(path, "a", encoding="utf-8") as f:
        f.write(line)


def read_jsonl(path: str | os.PathLike[str]) -> Iterator[dict[str, Any]]:
    """Records of a JSONL file that may still be written to; bad or torn lines are skipped."""
    try:
        f = open(path, encoding="utf-8", errors="replace")
    except FileNotFoundError:
        return
    with f:
        for line in f:
            try:
                rec = json.loads(line)
            except ValueError:
                continue
            if isinstance(rec, dict):
                yield rec


def _num(v: Any) -> float | None:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    return float(v) if math.isfinite(v) else None


def _first(r: Mapping[str, Any], *keys: str) -> float | None:
    for k in keys:
        if (v := _num(r.get(k))) is not None:
            return v
    return None


def _return_points(records: list[dict[str, Any]], role: str) -> tuple[list[float], list[float]]:
    """(env steps, return) for `role` ("train" or "eval"), one point per report that has one.

    Hub snapshots repeat the last return at every report, so there a point is kept only
    where the role's episode counter moved.
    """
    hub_ret = snapshot_key("wmdist_episode_return", role=role)
    hub_count = snapshot_key("wmdist_episodes_total", role=role)
    xs: list[float] = []
    ys: list[float] = []
    last_count: float | None = None
    for r in records:
        x = _first(r, "env_steps", HUB_STEPS)
        if x is None:
            continue
        if (y := _num(r.get(hub_ret))) is not None:
            n = _num(r.get(hub_count))
            if n is not None:
                if n == 0 or n == last_count:
                    continue
                last_count = n
        elif (y := _num(r.get(f"{role}_return"))) is None:
            continue
        elif role == "eval" and r.get("kind", "eval") != "eval":
            continue
        xs.append(x)
        ys.append(y)
    return xs, ys


def _loss_series(records: list[dict[str, Any]]) -> dict[str, tuple[list[float], list[float]]]:
    """name -> (updates, value) for every loss key seen (`loss/<name>` or the hub's spelling)."""
    out: dict[str, tuple[list[float], list[float]]] = {}
    for r in records:
        x = _first(r, "updates", HUB_UPDATES)
        if x is None:
            continue
        for k, v in r.items():
            if k.startswith(LOG_LOSS_PREFIX):
                name = k[len(LOG_LOSS_PREFIX) :]
            elif k.startswith(HUB_LOSS_PREFIX):
                name = k[len(HUB_LOSS_PREFIX) : -1]
            else:
                continue
            if (y := _num(v)) is not None:
                xs, ys = out.setdefault(name, ([], []))
                xs.append(x)
                ys.append(y)
    return out


def plot_learning_curve(jsonl_path: str | os.PathLike[str], png_path: str | os.PathLike[str]) -> None:
    """Draw returns vs env steps and losses vs updates; the PNG is replaced atomically."""
    records = list(read_jsonl(jsonl_path))
    fig = Figure(figsize=(11, 4.2), dpi=100)
    ax_ret, ax_loss = fig.subplots(1, 2)

    any_ret = False
    for role, style in (("train", "-"), ("eval", "o-")):
        xs, ys = _return_points(records, role)
        if xs:
            any_ret = True
            ax_ret.plot(xs, ys, style, markersize=3, label=role)
    ax_ret.set_xlabel("env steps")
    ax_ret.set_ylabel("episode return")
    ax_ret.set_title("returns")
    if any_ret:
        ax_ret.legend(loc="best")
    else:
        ax_ret.text(0.5, 0.5, "no episodes yet", ha="center", va="center", transform=ax_ret.transAxes)

    losses = _loss_series(records)
    for name, (xs, ys) in sorted(losses.items()):
        ax_loss.plot(xs, ys, label=name)
    ax_loss.set_xlabel("learner updates")
    ax_loss.set_ylabel("loss")
    ax_loss.set_title("losses")
    if losses:
        values = [y for _, ys in losses.values() for y in ys]
        if min(values) > 0 and max(values) / min(values) > 100:  # spans decades: log scale
            ax_loss.set_yscale("log")
        ax_loss.legend(loc="best", fontsize="small")
    else:
        ax_loss.text(0.5, 0.5, "no updates yet", ha="center", va="center", transform=ax_loss.transAxes)
    for ax in (ax_ret, ax_loss):
        ax.grid(alpha=0.3)
    fig.tight_layout()

    # Write beside the target and rename, so a viewer never sees a half-written PNG.
    png = Path(png_path)
    png.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=png.name + ".", suffix=".tmp", dir=png.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            fig.savefig(f, format="png")
        os.replace(tmp, png)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
