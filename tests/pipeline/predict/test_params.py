"""scipctl.pipeline.predict.params: the arm workspace and footprint models, and every params dataclass's check()."""

import math
from dataclasses import replace

import numpy as np
import pytest

from scipctl.pipeline import predict as P
from scipctl.pipeline.chain import ChainParams
from tests.pipeline.predict.helpers import start_pose


def test_arm_workspace_and_footprint_distance():
    arm = P.ArmWorkspace(0.6, 1.0, 0.4)
    pts = np.array([[0.8, 0.0], [0.59, 0.0], [1.01, 0.0], [0.8, 0.39], [0.8, 0.41], [-0.8, 0.0]])
    assert arm.contains(pts).tolist() == [True, False, False, True, False, False]
    body = P.RoverBody(0.5, -0.5, 0.4)
    d = body.distance(np.array([[0.0, 0.0], [0.8, 0.0], [0.5, 0.7], [-0.8, -0.8]]))
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
    (P.ApproachParams(arm=P.ArmWorkspace(half_width_m=-1.0)), "ArmWorkspace.half_width_m"),
    (P.UncertaintyParams(n_samples=0), "UncertaintyParams.n_samples: must be an integer >= 1, got 0"),
    (P.UncertaintyParams(n_samples=10.0), "UncertaintyParams.n_samples: must be an integer >= 1, got 10.0"),
    (P.UncertaintyParams(sigma_yaw_rad=-0.1), "UncertaintyParams.sigma_yaw_rad: must be a number >= 0 or None"),
    (P.PredictParams(min_coverage=2.0), "PredictParams.min_coverage: must be a number >= 0 and <= 1, got 2.0"),
    (P.PredictParams(uncertainty=P.UncertaintyParams(seed=-1)), "UncertaintyParams.seed: must be an integer >= 0"),
    (P.PredictParams(chain=ChainParams(fine_radius_px=0.0)), "ChainParams.fine_radius_px: must be a number > 0"),
    (ChainParams(template_half_px={"pancam": 20, "navcam": 0}), "ChainParams.template_half_px['navcam']: must be an integer >= 1"),
    (ChainParams(other_band_px=-1.0), "ChainParams.band_px['other cameras']: must be a number >= 0.0"),
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
