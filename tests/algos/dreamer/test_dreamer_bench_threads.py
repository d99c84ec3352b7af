"""`wmdist bench dreamer`'s learner-threads case: a preset's own learner, timed at 1 and 2
torch threads, leaves the process's thread count as it found it."""
from __future__ import annotations

import torch

from wmdist.bench.dreamer import _threads_case


def test_threads_case_times_the_presets_learner_and_restores_threads():
    before = torch.get_num_threads()
    case = _threads_case("dreamerv1_dmc_cartpole_balance", updates=1)
    assert torch.get_num_threads() == before
    assert case["batch"] == "16x50" and case["imag_starts"] == 128  # read from the preset, not a default
    assert case["seconds_per_update_1_thread"] > 0 and case["seconds_per_update_2_threads"] > 0
    ratio = case["seconds_per_update_1_thread"] / case["seconds_per_update_2_threads"]
    assert abs(case["speedup_2_threads"] - ratio) < 0.02
