"""`python -m wmdist.algos.jepa.collapse_plot`: the series it reads from a run's metrics, the PNG,
and a one-line error (exit 2) for an argument that is not a JEPA run."""
from __future__ import annotations

from pathlib import Path

from wmdist.algos.jepa.collapse_plot import main, series
from wmdist.telemetry.curves import write_jsonl


def _run(folder: Path, stds: list[float]) -> Path:
    folder.mkdir()
    for i, s in enumerate(stds):
        write_jsonl(folder / "metrics.jsonl", {"updates": 10 * i, "kind": "train", "loss/embed_std": s,
                                               "loss/effective_rank": 3.0, "loss/sigreg": 1.0})
    write_jsonl(folder / "metrics.jsonl", {"updates": 25, "kind": "eval", "eval_return": 0.5})
    return folder


def test_series_and_png(tmp_path):
    a = _run(tmp_path / "a", [1.0, 0.5, 0.1])
    b = _run(tmp_path / "b", [1.0, 1.0])
    assert series(a / "metrics.jsonl", "loss/embed_std") == ([0.0, 10.0, 20.0], [1.0, 0.5, 0.1])
    assert series(a / "metrics.jsonl", "eval_return") == ([25.0], [0.5])
    png = tmp_path / "out.png"
    assert main(["--png", str(png), f"sig={b}", f"nosig={a}"]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_arguments_are_one_line_and_exit_2(tmp_path, capsys):
    not_jepa = tmp_path / "dreamer"
    not_jepa.mkdir()
    write_jsonl(not_jepa / "metrics.jsonl", {"updates": 1, "loss/model_loss": 2.0})
    png = tmp_path / "out.png"
    for arg in ("no-equals-sign", f"x={tmp_path / 'missing'}", f"x={not_jepa}"):
        assert main(["--png", str(png), arg]) == 2
        err = capsys.readouterr().err.strip()
        assert err.startswith("collapse_plot: ") and "\n" not in err
    assert not png.exists()
