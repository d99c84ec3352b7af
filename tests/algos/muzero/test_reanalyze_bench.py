"""`wmdist bench reanalyze` (wmdist/bench/reanalyze.py) runs both cases and reports figures;
the memory and speed comparison itself is a benchmark (BENCHMARKS.md), not a test."""
from __future__ import annotations

from wmdist.bench import reanalyze


def test_reanalyze_bench_measures_both_cases():
    cases = list(reanalyze.run(quick=True))
    assert [c["case"] for c in cases] == ["unpadded", "padded"]
    for c in cases:
        assert c["roots_per_s"] > 0 and c["peak_rss_mb"] > 0 and c["max_rss_mb"] >= c["peak_rss_mb"] - 1
