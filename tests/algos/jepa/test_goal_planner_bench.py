"""`wmdist bench goal_planner` (wmdist/bench/goal_planner.py): one case per algorithm and E, with positive times."""
from __future__ import annotations

from wmdist.bench import goal_planner


def test_goal_planner_bench_times_both_planners():
    from wmdist.config.loader import load_config

    algo = load_config(str(goal_planner.PRESET)).algo
    planner = algo.planner
    cases = list(goal_planner.run(quick=True))
    assert [c["case"] for c in cases] == ["jepa_E1", "planet_E1", "jepa_E10", "planet_E10"]
    for c in cases:
        assert c["ms_per_decision"] > 0 and c["ms_per_decision_cpu"] > 0
        assert (c["horizon"], c["candidates"], c["top_k"], c["iterations"]) == (planner.horizon, planner.candidates,
                                                                                    planner.top_k, planner.iterations)
        # JEPA's time includes the preset's waypoint graph; PlaNet has none
        assert c["graph_nodes"] == (2 * algo.graph_pairs if c["algo"] == "jepa" else 0)
