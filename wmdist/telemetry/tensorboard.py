"""TensorBoard event files beside `metrics.jsonl`: where people who train these agents look first.

Every record the driver writes to `metrics.jsonl` becomes scalars under `<kind>/<key>` (for
example `train/loss/value`, `eval/eval_return`) at step = env steps, with the record's own
wall time; the learning-curve PNG becomes an image each time it is redrawn, and a dream or
evaluation video becomes an image sequence. Open with `tensorboard --logdir RUN_DIR/tensorboard`.
"""
from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Any

import numpy as np

TB_DIR = "tensorboard"
_NOT_SCALARS = {"time", "env_steps", "kind"}  # the step and the tag's prefix, not series


def scalars_of(record: dict) -> dict[str, float]:
    """The scalars one metrics.jsonl record contributes, keyed by TensorBoard tag."""
    kind = str(record.get("kind", "train"))
    out: dict[str, float] = {}
    for key, value in record.items():
        if key in _NOT_SCALARS or isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        if not math.isfinite(float(value)):
            continue
        out[f"{kind}/{key}"] = float(value)
    return out


class TensorBoardLog:
    """One run's event writer (torch's SummaryWriter over the tensorboard package)."""

    def __init__(self, run_dir: str | Path) -> None:
        from torch.utils.tensorboard import SummaryWriter

        self.dir = Path(run_dir) / TB_DIR
        self.writer = SummaryWriter(log_dir=str(self.dir), flush_secs=10)
        self.t0 = time.time()

    def record(self, record: dict) -> None:
        """Write one metrics.jsonl record's scalars at its env step."""
        step = int(record.get("env_steps", 0))
        wall = self.t0 + float(record.get("time", 0.0))
        for tag, value in scalars_of(record).items():
            self.writer.add_scalar(tag, value, global_step=step, walltime=wall)

    def image(self, tag: str, png_path: str | Path, step: int) -> None:
        """A PNG file (the learning curve) as an image at `step`."""
        import imageio.v3 as iio

        img = np.asarray(iio.imread(str(png_path)))  # [H, W, C] uint8
        if img.ndim == 2:
            img = img[:, :, None]
        self.writer.add_image(tag, img[:, :, :3], global_step=step, dataformats="HWC")

    def frames(self, tag: str, frames: Any, fps: int = 10) -> None:
        """A video's frames ([T, H, W, C] uint8) as an image sequence (steps = frame index), which
        needs nothing beyond TensorBoard itself (its video panel needs moviepy)."""
        arr = np.asarray(frames)
        for t, frame in enumerate(arr):
            self.writer.add_image(tag, frame[:, :, :3] if frame.ndim == 3 else frame[:, :, None],
                                  global_step=t, dataformats="HWC")

    def flush(self) -> None:
        self.writer.flush()

    def close(self) -> None:
        self.writer.close()


def read_scalars(logdir: str | Path) -> dict[str, list[tuple[int, float]]]:
    """Every scalar series in `logdir`, read with TensorBoard's own event reader: tag ->
    [(step, value)] in write order."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(logdir), size_guidance={"scalars": 0, "images": 0})
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


def read_image_tags(logdir: str | Path) -> list[str]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(logdir), size_guidance={"images": 0})
    acc.Reload()
    return list(acc.Tags()["images"])
