"""scipctl.pipeline.predict.arm_margin: the final drive's error at the arm, against the Monte Carlo it models, and
the standoff search keeping that margin inside the arm workspace."""

from dataclasses import replace

import numpy as np
import pytest

from scipctl.pipeline import predict as P
from scipctl.pipeline.predict.approach_search import ARM_MARGIN, ROCK
from scipctl.pipeline.predict.arm_margin import arm_margin
from tests.pipeline.predict.helpers import box_fn, heightfield_source, start_pose

T = np.array([9.0, 0.0, 0.0])
# a 0.3 m rock beside the direct approach line, 0.2-0.35 m before the target: on the direct bearing every
# standoff but the workspace's edge (1.0 m) brings the footprint within rock-keep-out of it
SIDE_ROCK = (8.65, 0.25, 8.8, 0.5, 0.3)


def _margin_of(plan, rc, up):
    sp, sy = up.per_stop_sigmas()
    X = plan.final.T_site_rover.inverse().apply(T)
    return arm_margin([s.leg_m for s in plan.stops[1:]], X, rc, up, 2.0, sp, sy)


@pytest.mark.parametrize("standoff_m", [0.8, 1.0])
def test_the_margin_model_matches_the_monte_carlo_final_arm_point(rc, flat_terrain, standoff_m):
    up = P.UncertaintyParams(n_samples=20000, seed=3)
    plan = P.plan_approach(start_pose(), T, flat_terrain, rc, P.ApproachParams(standoff_m=standoff_m))
    am = _margin_of(plan, rc, up)
    assert am.sigma_pose_m == 0.0 and am.sigma_m == am.sigma_stereo_m > 0  # a hazcam: only the stereo error
    mc = P.monte_carlo(plan, flat_terrain, rc, T, up, *up.per_stop_sigmas())
    r = np.hypot(*mc.final_xy_rover_m.T)
    # the model's spread vs the samples': measured 0.74 % (1.0 m) and 0.93 % (0.8 m) at the test's seed 3, 0.0 % and
    # 0.73 % at seed 0, identical on OpenCV 5.0 and 4.14, 1 and 2 threads (seeded numpy draws); the sample std of
    # 20000 near-normal samples has a standard error of 0.5 %: bound 3 %, 6 of them (3.2x the worst measured)
    assert r.std() == pytest.approx(am.sigma_m, rel=0.03)
    # no bias (the correction along the true heading cancels the pose error): the sample mean's offset measured
    # 0.91 (1.0 m) and 1.15 (0.8 m) of its standard error sigma / sqrt(n) at seed 3, 0.16-0.18 at seed 0 (the same
    # on OpenCV 5.0 and 4.14, 1 and 2 threads); bound 4 of them (3.5x the worst measured; a 4-sigma event is 6e-5)
    assert abs(r.mean() - standoff_m) <= 4 * r.std() / np.sqrt(r.size)
    # 2 sigma beyond each limit: measured 2.4-3.3 % of the samples per side at seed 3 (2.6-3.1 % at seed 0), the
    # same on OpenCV 5.0 and 4.14, 1 and 2 threads (a normal leaves 2.3 %; the stereo error's spread varies with the
    # line of sight, a mixture of normals); bound 4.5 % per side, 1.36x the worst measured (3.30 %)
    assert np.mean(r > standoff_m + am.margin_m) <= 0.045
    assert np.mean(r < standoff_m - am.margin_m) <= 0.045


def test_without_a_final_re_estimate_the_margin_is_the_position_random_walk(rc):
    up = P.UncertaintyParams(drive_error_frac=0.02)
    no_haz = replace(rc, cameras={k: v for k, v in rc.cameras.items() if k != "hazcam"})
    am = arm_margin([4.0, 3.0], np.array([0.8, 0.0, 0.0]), no_haz, up, 2.0, 0.03, 0.01)
    var_xy = 2 * 0.03 ** 2 + (0.02 * 4.0) ** 2 + (0.02 * 3.0) ** 2
    # the model is this closed form: equal up to float64 rounding of a handful of operations (~1e-16 relative;
    # measured exactly equal on OpenCV 5.0 and 4.14, 1 and 2 threads): rel 1e-12 is a float-identity tolerance
    assert am.sigma_stereo_m == 0.0 and am.sigma_pose_m == pytest.approx(np.sqrt(var_xy), rel=1e-12)
    assert am.margin_m == pytest.approx(2.0 * np.sqrt(var_xy), rel=1e-12)


def test_a_blocked_centre_no_longer_ends_at_the_workspace_edge(rc):
    ter = P.Terrain([heightfield_source(box_fn([SIDE_ROCK]))], smooth_sigma_px=0)
    old = P.plan_approach(start_pose(), T, ter, rc)  # no error model: the search as before
    arm = old.params.arm
    # the standoff grid (centre +- k * standoff_step_m, rounded to 1e-9 m) reaches r_max_m on the default 0.6-1.0 m
    # workspace, so the edge plan's standoff is r_max_m itself (measured exactly equal): approx's default rel 1e-6
    # only absorbs that rounding
    assert old.detour_rad == 0.0 and old.params.final_distance_m == pytest.approx(arm.r_max_m)
    up = P.UncertaintyParams()
    new = P.plan_approach(start_pose(), T, ter, rc, uncertainty=up)
    s = new.search
    assert s.found_with_margin and s.margin_binding() == []
    assert s.tried[s.kept]["bound_by"] == [] and not s.tried[s.kept]["short_of_margin"]
    # the edge plan was tried, cleared the flight rules and was passed over for its missing room
    edge = [t for t in s.tried if t["detour_deg"] == 0.0 and t["standoff_m"] == pytest.approx(arm.r_max_m)]
    assert edge and edge[0]["bound_by"] == [] and edge[0]["short_of_margin"]
    xy = new.final.T_site_rover.inverse().apply(T)[:2]
    room = min(np.hypot(*xy) - arm.r_min_m, arm.r_max_m - np.hypot(*xy))
    # the search's own rule (room >= margin), not a measured bound; measured room 0.100 m, margin 0.0067 m
    assert new.arm_margin is not None and room >= new.arm_margin.margin_m > 0
    assert not new.clearance["blocked"]
    d = new.to_dict()
    assert d["arm_margin"]["margin_m"] == new.arm_margin.margin_m and d["search"]["found_with_margin"]


def test_when_no_candidate_has_the_margin_the_edge_plan_is_kept_and_the_binding_rule_named(rc, flat_terrain):
    ter = P.Terrain([heightfield_source(box_fn([SIDE_ROCK]))], smooth_sigma_px=0)
    up = P.UncertaintyParams()
    direct_only = P.ApproachParams(detour_bearings_rad=(0.0,))
    plan = P.plan_approach(start_pose(), T, ter, rc, direct_only, uncertainty=up)
    s = plan.search
    assert s.found and not s.found_with_margin
    assert plan.params.final_distance_m == pytest.approx(plan.params.arm.r_max_m)  # the first clear plan
    assert s.margin_binding() == [ROCK]
    msg = s.describe_margin()
    assert "the candidates with that room break rock-keep-out" in msg and "approach.arm_margin_sigmas" in msg
    # a workspace narrower than the margin: no standoff has the room; the centre is kept and the message says so
    # room 0.002 m against a margin of 0.00445 m at the 0.8 m centre (measured, the same on OpenCV 5.0 and 4.14,
    # 1 and 2 threads): 2.2x short, so no standoff has the room by design of the case
    narrow = P.ApproachParams(arm=P.ArmWorkspace(r_min_m=0.798, r_max_m=0.802))
    plan2 = P.plan_approach(start_pose(), T, flat_terrain, rc, narrow, uncertainty=up)
    assert plan2.search.margin_binding() == [ARM_MARGIN]
    assert plan2.params.final_distance_m == pytest.approx(0.8)  # the workspace centre, (0.798 + 0.802) / 2
    assert "no standoff inside the workspace has that room" in plan2.search.describe_margin()


def test_a_pinned_standoff_or_zero_sigmas_asks_no_margin(rc, flat_terrain):
    up = P.UncertaintyParams()
    pinned = P.plan_approach(start_pose(), T, flat_terrain, rc, P.ApproachParams(standoff_m=1.0), uncertainty=up)
    assert pinned.arm_margin is None and pinned.params.final_distance_m == 1.0
    off = P.plan_approach(start_pose(), T, flat_terrain, rc, P.ApproachParams(arm_margin_sigmas=0.0),
                          uncertainty=up)
    assert off.arm_margin is None and not off.search.tried[off.search.kept]["short_of_margin"]
