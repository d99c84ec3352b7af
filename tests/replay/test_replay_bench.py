"""`wmdist bench replay --quick` end to end on the session's real Ray: one row per service with
its raw limit, figures timed over blocks of calls, exact reads, and the memory per stored step."""
from __future__ import annotations

from wmdist.bench import replay


def test_quick_bench_rows(ray_session):
    rows = list(replay.run(quick=True))
    services = {r["backend"]: r for r in rows if "backend" in r}
    assert set(services) == {"memory", "memory-actor", "redis"}
    for r in services.values():
        assert r["insert_seq_per_s"] > 0 and r["sample_seq_per_s"] > 0 and r["insert_vs_raw"] > 0
    assert services["memory"]["calls_per_round"] == [4, 32]  # a stock's gather is inside the figure
    assert services["memory"]["stale_reads"] == 0 and services["memory"]["memory_vs_raw"] <= 1.1
    assert services["redis"]["sample_vs_raw_ahead"] > 0
    assert any(r.get("compare", "").startswith("memory (shm) / redis") for r in rows)
