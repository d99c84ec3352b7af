"""The MCTS bench runs and the engine beats the plain-Python reference in the same run."""
from __future__ import annotations

import torch

from wmdist.bench import mcts

torch.set_num_threads(1)


def test_bench_cases_report_rates_and_beat_the_reference() -> None:
    ref = mcts._reference_rate(18)
    tree = mcts._tree_case(64, 18, ref, repeats=3)
    assert tree["sims_per_s"] > 0 and tree["vs_reference_cpu"] > 3.0, tree
    mlp = mcts._mlp_case(8, 2, repeats=2)
    assert 0.0 < mlp["tree_fraction_cpu"] < 1.0 and mlp["forward_per_cpu_s"] > 0, mlp


def test_value_prefix_cases_run_beside_the_plain_ones() -> None:
    ref = mcts._reference_rate(18, prefix=True)
    tree = mcts._tree_case(8, 18, ref, repeats=2, prefix=True)
    assert tree["kind"] == "tree_prefix" and tree["sims_per_s"] > 0 and tree["vs_reference_cpu"] > 1.0, tree
    mlp = mcts._mlp_case(8, 2, repeats=2, lstm=True)
    assert mlp["kind"] == "mlp_lstm" and 0.0 < mlp["tree_fraction_cpu"] < 1.0, mlp
