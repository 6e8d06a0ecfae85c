"""The downlink's own route as the predicted approach (scipctl/pipeline/predict/route.py), on a bundled sol."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from scipctl.campaign.options import CampaignOptions
from scipctl.errors import InputError
from scipctl.io.downlink import read_downlink
from scipctl.pipeline.chain import ChainParams
from scipctl.pipeline.predict import resolve_target
from scipctl.pipeline.predict.montecarlo import monte_carlo
from scipctl.pipeline.predict.params import ApproachParams, PredictParams, UncertaintyParams
from scipctl.pipeline.predict.route import route_from_downlink, stop_kind

SOL = Path(__file__).resolve().parents[3] / "sample_sols" / "mcap" / "paper-s1-straight.mcap"


@pytest.fixture(scope="module")
def sol():
    dl = read_downlink(SOL)
    rec, _ = resolve_target(dl, dl.targets[0].id, None, with_normal=False)
    prod = dl.product(rec.product_id)
    return dl, rec, prod


def _route(dl, rec, prod):
    return route_from_downlink(dl, prod.pose, prod.position, rec.xyz_site_m, None, ApproachParams(), ChainParams(),
                               designation_camera=prod.camera)


def test_the_route_is_the_downlinks_later_stops_at_their_recorded_poses(sol):
    dl, rec, prod = sol
    plan = _route(dl, rec, prod)
    later = dl.positions()[dl.positions().index(prod.position) + 1:]
    assert len(plan.stops) == 1 + len(later) and plan.placement is False
    assert plan.stops[0].T_site_rover is prod.pose.T_site_rover
    prev_xy = prod.pose.T_site_rover.t[:2]
    # the route copies the recorded poses and sums its legs from the same numbers: the 1e-12 m tolerances are
    # float-identity ones (measured exactly 0 for positions, legs and path length on OpenCV 5.0 and 4.14, 1 and
    # 2 threads; path 8.93 m)
    for st, pos in zip(plan.stops[1:], later):
        lefts = dl.images_at(pos, eye="left")
        cams = {im.camera for im in lefts}
        assert np.allclose(st.T_site_rover.t[:2], lefts[0].pose.T_site_rover.t[:2], rtol=0, atol=1e-12)
        assert st.kind == stop_kind(cams)
        assert [c.camera for c in st.cameras] == [c for c in ("pancam", "navcam", "hazcam") if c in cams]
        assert st.leg_m == pytest.approx(float(np.linalg.norm(st.T_site_rover.t[:2] - prev_xy)), abs=1e-12)
        prev_xy = st.T_site_rover.t[:2]
    assert plan.path_length_m == pytest.approx(sum(st.leg_m for st in plan.stops[1:]), abs=1e-12)
    # the downlink's last stop images the target with the hazcam: the route ends at a navcam->hazcam handoff
    assert plan.stops[-1].kind == "navcam-hazcam-handoff"


def test_no_pose_error_means_every_view_of_the_route_is_ok_and_no_arm_check(sol):
    """Exact truth: with no pose, drive or stereo error the re-pointed target sits on its nominal pixel, so each
    view of the Monte Carlo is ok in every sample or in none, as its nominal shot is in view or not; the hazcam
    stop faces the designated point, so every shot of this sol is in view; a route ending at an imaging stop has
    no arm figure."""
    dl, rec, prod = sol
    plan = _route(dl, rec, prod)
    X = np.asarray(rec.xyz_site_m, float)
    for st in plan.stops[1:]:
        if any(sh.camera == "hazcam" for sh in st.cameras):
            xy = st.T_site_rover.t[:2]
            # the route's hazcam heading is this atan2 (measured exactly equal): a float-identity tolerance
            assert st.heading_rad == pytest.approx(math.atan2(X[1] - xy[1], X[0] - xy[0]), abs=1e-12)
    up = UncertaintyParams(drive_error_frac=0.0, yaw_error_rad_per_m=0.0, disparity_sigma_px=0.0, n_samples=50)
    mc = monte_carlo(plan, None, dl.rover_config, rec.xyz_site_m, up, 0.0, 0.0, 0.0)
    assert mc.p_arm_workspace is None and mc.final_xy_rover_m is None
    shots = [(st.index, sh.camera, sh.in_fov) for st in plan.stops[1:] for sh in st.cameras]
    assert [(v.stop, v.camera) for v in mc.views] == [s[:2] for s in shots]
    assert all(s[2] for s in shots)
    assert [v.p_ok for v in mc.views] == [1.0] * len(shots) and mc.p_success_geometry == 1.0
    # with the default drive error the long legs of the route cost views, and P is the fraction of good samples
    mc = monte_carlo(plan, None, dl.rover_config, rec.xyz_site_m, UncertaintyParams(n_samples=400), 0.01,
                     math.radians(0.5), 0.0)
    # the same fraction computed two ways: exact (abs=0); measured 0.6775 on OpenCV 5.0 and 4.14, 1 and 2 threads
    assert mc.p_success_geometry == pytest.approx(float(np.mean(mc.samples_ok)), abs=0)
    assert mc.p_success_geometry == min(v.p_chain for v in mc.views)


def test_a_downlink_without_later_stops_has_no_route(sol):
    dl, rec, prod = sol
    only_today = replace(dl, images=[im for im in dl.images if im.position == prod.position])
    with pytest.raises(InputError, match="positions"):
        _route(only_today, rec, prod)


def test_stop_kinds_follow_the_cameras_imaged():
    assert stop_kind({"pancam"}) == "pancam"
    assert stop_kind({"pancam", "navcam"}) == "pancam-navcam-handoff"
    assert stop_kind({"navcam", "hazcam"}) == "navcam-hazcam-handoff"
    with pytest.raises(ValueError, match="no chain stop"):
        stop_kind({"pancam", "hazcam"})


def test_route_is_checked_in_the_prediction_and_the_campaign_options():
    with pytest.raises(ValueError, match="route"):
        replace(PredictParams(), route="truth").check()
    assert replace(PredictParams(), route="downlink").check().route == "downlink"
    with pytest.raises(InputError, match="--predict-route"):
        CampaignOptions(handoff=False, predict_route="truth").check()
    opt = CampaignOptions(handoff=False, predict_route="downlink").check()
    assert CampaignOptions.from_dict(opt.to_dict()) == opt
    old = opt.to_dict()
    del old["predict_route"]  # a manifest written before the option: the planner's route
    assert CampaignOptions.from_dict(old).predict_route == "plan"
    assert CampaignOptions(handoff=False).key() != opt.key()
