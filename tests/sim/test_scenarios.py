"""Scenario plans: stops, cameras and distances of the traverse (scipctl/sim/scenarios.py)."""

import numpy as np

from scipctl.sim.scenarios import list_runs, plan_run


def test_traverse_plan():
    for run in list_runs("traverse"):
        plan = plan_run("traverse", run, 1)
        d = [np.linalg.norm(s.xy_m) for s in plan.stops]
        assert all(b < a for a, b in zip(d, d[1:]))
        cams = [s.cameras for s in plan.stops]
        assert cams[0] == ("pancam",) and "hazcam" in cams[-1]
        assert any("pancam" in c and "navcam" in c for c in cams), "a pancam->navcam handoff stop"
        first_haz = next(i for i, c in enumerate(cams) if "hazcam" in c)
        assert all("hazcam" in c for c in cams[first_haz:])
        # steps are 10-20 % of the remaining distance except where a stop is forced (handoffs, the end)
        mast_d = [np.linalg.norm(s.xy_m + 0.37 * np.array([np.cos(s.yaw_rad), np.sin(s.yaw_rad)])) for s in plan.stops]
        frac = [1 - b / a for a, b in zip(mast_d, mast_d[1:])]
        assert sum(0.099 < f < 0.201 for f in frac) >= len(frac) - 4
