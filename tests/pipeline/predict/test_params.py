"""scipctl.pipeline.predict.params: the arm workspace and footprint models, and every params dataclass's check()."""

import math
from dataclasses import replace

import numpy as np
import pytest

from scipctl.pipeline import predict as P
from scipctl.core.point_stereo import PointStereoParams
from scipctl.pipeline.chain import ChainParams
from tests.pipeline.predict.helpers import start_pose


def test_arm_workspace_and_footprint_distance():
    arm = P.ArmWorkspace(0.6, 1.0, 0.4)
    pts = np.array([[0.8, 0.0], [0.59, 0.0], [1.01, 0.0], [0.8, 0.39], [0.8, 0.41], [-0.8, 0.0]])
    assert arm.contains(pts).tolist() == [True, False, False, True, False, False]
    body = P.RoverBody(0.5, -0.5, 0.4)
    d = body.distance(np.array([[0.0, 0.0], [0.8, 0.0], [0.5, 0.7], [-0.8, -0.8]]))
    # exact distances to the footprint rectangle: float rounding only (measured 5.6e-17 m, identical on OpenCV 5.0
    # and 4.14, 1 and 2 threads); allclose's default 1e-8 + 1e-5 relative is a float-identity tolerance
    assert np.allclose(d, [0.0, 0.3, 0.3, math.hypot(0.3, 0.4)])


@pytest.mark.parametrize("cls", [P.ArmWorkspace, P.RoverBody, P.ApproachParams, P.UncertaintyParams, P.PredictParams,
                                 ChainParams])
def test_defaults_pass_check(cls):
    p = cls()
    assert p.check() is p


# (params with one bad value, the start of the error message)
BAD = [
    (P.ArmWorkspace(r_min_m=1.0, r_max_m=0.5), "ArmWorkspace.r_max_m: must be a number > r_min_m (1)"),
    (P.ArmWorkspace(half_width_m=0.0), "ArmWorkspace.half_width_m: must be a number > 0"),
    (P.RoverBody(front_m=-0.6), "RoverBody.rear_m: must be < front_m (-0.6)"),
    (P.RoverBody(front_m=float("nan")), "RoverBody.front_m: must be a number, got nan"),
    (P.ApproachParams(stop_fraction=1.5), "ApproachParams.stop_fraction: must be a number > 0 and <= 1"),
    (P.ApproachParams(hazcam_handoff_m=5.0), "ApproachParams.pancam_handoff_m: must be a number > hazcam_handoff_m (5)"),
    (P.ApproachParams(detour_bearings_rad=(0.2, 0.0)), "ApproachParams.detour_bearings_rad: must start with 0.0"),
    (P.ApproachParams(standoff_m=-1.0), "ApproachParams.standoff_m: must be a number > 0 or None"),
    (P.ApproachParams(standoff_step_m=1e-6), "ApproachParams.standoff_step_m: must be a number >= 0.01, got 1e-06"),
    (P.ApproachParams(arm=P.ArmWorkspace(half_width_m=-1.0)), "ArmWorkspace.half_width_m"),
    (P.UncertaintyParams(n_samples=0), "UncertaintyParams.n_samples: must be an integer >= 1, got 0"),
    (P.UncertaintyParams(n_samples=10.0), "UncertaintyParams.n_samples: must be an integer >= 1, got 10.0"),
    (P.UncertaintyParams(sigma_yaw_rad=-0.1), "UncertaintyParams.sigma_yaw_rad: must be a number >= 0 or None"),
    (P.PredictParams(min_coverage=2.0), "PredictParams.min_coverage: must be a number >= 0 and <= 1, got 2.0"),
    (P.PredictParams(uncertainty=P.UncertaintyParams(seed=-1)), "UncertaintyParams.seed: must be an integer >= 0"),
    (P.PredictParams(chain=ChainParams(fine_radius_px=0.0)), "ChainParams.fine_radius_px: must be a number > 0"),
    (ChainParams(template_half_px={"pancam": 20, "navcam": 0}), "ChainParams.template_half_px['navcam']: must be an integer >= 1"),
    (ChainParams(point_stereo=PointStereoParams(other_band_px=-1.0)),
     "PointStereoParams.band_px['other cameras']: must be a finite number >= 0"),
    (P.ApproachParams(fov_margin_px={"pancam": -1}), "ApproachParams.fov_margin_px['pancam']: must be an integer >= 0"),
    (P.ApproachParams(other_fov_margin_px=2.5), "ApproachParams.other_fov_margin_px: must be an integer >= 0"),
    (P.PredictParams(success_m={"hazcam": 0.0}), "PredictParams.success_m['hazcam']: must be a number > 0"),
    (P.PredictParams(other_success_m=float("inf")), "PredictParams.other_success_m: must be a number > 0"),
    (P.PredictParams(min_success_px=-1.0), "PredictParams.min_success_px: must be a number >= 0"),
    (P.PredictParams(lost_m=0.0), "PredictParams.lost_m: must be a number > 0"),
    (ChainParams(feature_step_factors=()), "ChainParams.feature_step_factors: must be a non-empty tuple"),
    (ChainParams(feature_candidates=((0.15, "affine", 6),)), "ChainParams.feature_candidates: each must be"),
]


@pytest.mark.parametrize("params, message", BAD, ids=[m.split(":")[0] for _, m in BAD])
def test_a_bad_value_fails_check_with_a_message_naming_it(params, message):
    with pytest.raises(ValueError) as e:
        params.check()
    assert str(e.value).startswith(message), str(e.value)


def test_the_prediction_checks_its_params_before_planning(rc, flat_terrain):
    with pytest.raises(ValueError, match="ApproachParams.min_leg_m"):
        P.plan_approach(start_pose(), np.array([9.0, 0.0, 0.0]), flat_terrain, rc, replace(P.ApproachParams(), min_leg_m=0))


def test_planned_shots_carry_the_chain_windows(rc, flat_terrain):
    """The planned shots take their window and search radius from ChainParams (the on-board chain's)."""
    T = np.array([9.0, 0.0, 0.0])
    default = P.plan_approach(start_pose(), T, flat_terrain, rc)
    cp = ChainParams(template_half_px={"pancam": 12, "navcam": 9, "hazcam": 7},
                     search_radius_px={"pancam": 200.0, "navcam": 90.0, "hazcam": 70.0})
    custom = P.plan_approach(start_pose(), T, flat_terrain, rc, chain_params=cp)
    shots = [sh for st in custom.stops[1:] for sh in st.cameras]
    assert {sh.camera for sh in shots} == {"pancam", "navcam", "hazcam"}
    for sh in shots:
        assert (sh.template_half_px, sh.search_radius_px) == (cp.template_half_px[sh.camera], cp.search_radius_px[sh.camera])
    for sh in (sh for st in default.stops[1:] for sh in st.cameras):
        assert sh.template_half_px == ChainParams().template_half(sh.camera)


def test_planned_shots_judge_the_field_of_view_by_the_approach_margin(rc, flat_terrain):
    """ApproachParams.fov_margin_px is the planner's in-view margin: a margin of half the image puts no target in
    view; the default keeps the shots in view on this open terrain."""
    T = np.array([9.0, 0.0, 0.0])
    default = P.plan_approach(start_pose(), T, flat_terrain, rc)
    assert all(sh.in_fov for st in default.stops[1:] for sh in st.cameras)
    half = max(max(rc.spec(c, "left").width, rc.spec(c, "left").height) for c in ("pancam", "navcam", "hazcam")) // 2
    wide = P.ApproachParams(fov_margin_px={}, other_fov_margin_px=half)
    blind = P.plan_approach(start_pose(), T, flat_terrain, rc, wide)
    assert not any(sh.in_fov for st in blind.stops[1:] for sh in st.cameras)


def test_success_tolerance_follows_the_prediction_params():
    """success_px: the camera's accuracy goal on the surface in pixels at the range, at least min_success_px."""
    from scipctl.core.camera import cahv_from_intrinsics
    from scipctl.core.transforms import RigidTransform

    m = cahv_from_intrinsics(1000.0, 1000.0, 500.0, 500.0, RigidTransform.identity())  # hs = 1000 px per radian
    p = P.PredictParams()
    # success_px is this closed form (goal x focal length / range): rel 1e-12 is a float-identity tolerance
    # (measured exactly equal, here and in the 4x case below, on OpenCV 5.0 and 4.14, 1 and 2 threads)
    assert P.success_px(m, 2.0, "hazcam", p) == pytest.approx(p.success_of("hazcam") * m.hs / 2.0, rel=1e-12)
    assert P.success_px(m, 100.0, "hazcam", p) == p.min_success_px  # 0.1 px on the surface: the floor
    loose = P.PredictParams(success_m={"hazcam": 0.04})
    assert P.success_px(m, 2.0, "hazcam", loose) == pytest.approx(4 * P.success_px(m, 2.0, "hazcam", p), rel=1e-12)
    assert p.success_of("chemcam") == p.other_success_m


def test_tracker_reach_and_route_are_checked():
    from dataclasses import replace

    from scipctl.pipeline.predict.params import PredictParams

    assert PredictParams().tracker_reach == "image" and PredictParams().route == "plan"
    for field, bad in (("tracker_reach", "anywhere"), ("route", "truth")):
        with pytest.raises(ValueError, match=field):
            replace(PredictParams(), **{field: bad}).check()
