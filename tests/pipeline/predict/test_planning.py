"""scipctl.pipeline.predict.planning: the stop schedule, straight plans and detours around rocks."""

import numpy as np
import pytest

from scipctl.pipeline import predict as P
from tests.pipeline.predict.helpers import box_fn, heightfield_source, start_pose


def test_stop_distances_follow_the_paper_schedule():
    p = P.ApproachParams()
    stops = P.stop_distances(10.0, p)
    d = [s[0] for s in stops]
    kinds = dict((round(x, 6), k) for x, k in stops)
    assert all(a > b for a, b in zip(d, d[1:]))
    assert kinds[p.pancam_handoff_m] == "pancam-navcam-handoff"
    assert kinds[p.hazcam_handoff_m] == "navcam-hazcam-handoff"
    assert kinds[1.4] == "hazcam" and stops[-1] == (p.final_distance_m, "final")
    # the schedule is arithmetic on distances <= 10 m (an ulp is 1.8e-15 m): 1e-9 m is a float-identity slack.
    # Measured: regular legs 4.4e-16 m off the rule; special stops at least 0.25 m inside step + merge_m (identical
    # on OpenCV 5.0 and 4.14, 1 and 2 threads)
    prev = 10.0
    for x, k in stops:
        step = max(p.stop_fraction * prev, p.min_leg_m)
        if k in ("pancam", "navcam"):  # regular stops: stop_fraction of the remaining distance from the last stop
            assert prev - x == pytest.approx(step, abs=1e-9)
            assert k == ("pancam" if x > p.pancam_handoff_m else "navcam")
        elif prev > p.hazcam_handoff_m:  # a special stop replaces a regular one that would come too close to it
            assert prev - x <= step + p.merge_m + 1e-9
        prev = x
    near = P.stop_distances(3.0, p)  # starting inside the pancam range: the first stop hands off
    assert near[0][1] == "pancam-navcam-handoff" and all(k != "pancam" for _, k in near)
    assert P.stop_distances(0.7, p) == []


def test_straight_plan_on_flat_ground(rc, flat_terrain):
    T = np.array([9.0, 1.0, 0.0])
    plan = P.plan_approach(start_pose(), T, flat_terrain, rc)
    assert plan.detour_rad == 0.0 and not plan.clearance["blocked"]
    u = T[:2] / np.linalg.norm(T[:2])
    # on flat ground the plan is exact geometry: the 1e-9 tolerances are float-identity ones (~10 m coordinates,
    # ulp 1.8e-15 m). Measured (identical on OpenCV 5.0 and 4.14, 1 and 2 threads): off the line 1.1e-16 m,
    # distance 0, z and tilt exactly 0 (1e-6 asks only that the flat ground gives a level pose), final distance
    # 5.6e-16 m, path length 0, target in the final frame 6.7e-16 m
    for st in plan.stops[1:]:
        xy = st.T_site_rover.t[:2]
        assert abs(u[0] * xy[1] - u[1] * xy[0]) < 1e-9  # on the line start -> target
        assert st.distance_m == pytest.approx(np.linalg.norm(T[:2] - xy), abs=1e-9)
        assert abs(st.T_site_rover.t[2]) < 1e-6 and st.tilt_rad < 1e-6
        for sh in st.cameras:
            assert sh.in_fov and sh.uv is not None
            if sh.pan_rad is not None:  # mast cameras centred on the target
                # 1e-3 px is RoverConfig.point_at's own acceptance limit (it raises beyond it); measured 2.8e-13 px
                spec = rc.spec(sh.camera, "left")
                assert np.allclose(sh.uv, [(spec.width - 1) / 2, (spec.height - 1) / 2], atol=1e-3)
    fin = plan.final
    assert fin.kind == "final" and fin.distance_m == pytest.approx(plan.params.final_distance_m, abs=1e-9)
    assert plan.path_length_m == pytest.approx(np.linalg.norm(T[:2]) - plan.params.final_distance_m, abs=1e-9)
    xy_r = fin.T_site_rover.inverse().apply(T)[:2]
    assert np.allclose(xy_r, [plan.params.final_distance_m, 0.0], atol=1e-9)


def test_plan_detours_around_a_rock_and_reports_a_blocked_approach(rc):
    T = np.array([9.0, 0.0, 0.0])
    rock = (4.5, -0.4, 5.2, 0.4, 0.4)  # on the direct line
    ter = P.Terrain([heightfield_source(box_fn([rock]))], smooth_sigma_px=0)
    plan = P.plan_approach(start_pose(), T, ter, rc)
    assert plan.detour_rad != 0.0
    # the planner's rule (rock_keep_out_m 0.15 m), not a measured bound: measured 0.228 m at a 15 deg detour
    assert plan.clearance["min_rock_m"] >= plan.params.rock_keep_out_m and not plan.clearance["blocked"]
    wall = (6.0, -4.0, 6.3, 4.0, 0.5)  # a wall across every approach
    ter2 = P.Terrain([heightfield_source(box_fn([wall]))], smooth_sigma_px=0)
    plan2 = P.plan_approach(start_pose(), T, ter2, rc)
    assert plan2.clearance["blocked"] and plan2.clearance["min_rock_m"] < plan2.params.rock_keep_out_m
