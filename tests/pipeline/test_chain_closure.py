"""The closure check's reference choice and its evidence's path (pipeline/chain_closure.py); its run on real chains is
in test_chain.py."""

import math

import numpy as np

from scipctl.pipeline.chain import ChainParams, ChainStep
from scipctl.pipeline.chain_closure import CLOSURE_REFERENCES, Closure, closure_reference

import pytest


def _step(camera, kind, pos, ok=True, unverified=False, uv=(1.0, 2.0), xyz=(1.0, 0.0, 0.0), final=False):
    extra = {"unverified": unverified}
    if final:
        extra["final"] = True
    return ChainStep(pos, camera, f"{camera}-{pos[1]}", kind, None, None if uv is None else list(uv), None, None, None,
                     None, None if xyz is None else list(xyz), None, None, ok, "", extra)


def test_the_reference_is_the_last_trusted_pancam_track():
    steps = [_step("pancam", "designate", (1, 0)), _step("pancam", "track", (1, 1)), _step("navcam", "handoff", (1, 1)),
             _step("pancam", "track", (1, 2)), _step("navcam", "track", (1, 3)), _step("hazcam", "handoff", (1, 3), final=True)]
    assert closure_reference(steps, 5) == 3
    steps[3] = _step("pancam", "track", (1, 2), ok=False)  # a flagged track is no reference
    assert closure_reference(steps, 5) == 1
    steps[1] = _step("pancam", "track", (1, 1), unverified=True)
    assert closure_reference(steps, 5) == 2  # no trusted pancam track: the navcam handoff at the imaging stop
    steps[1] = _step("pancam", "track", (1, 1), xyz=None)  # no stereo point: nothing to render through
    assert closure_reference(steps, 5) == 2
    steps[2] = _step("navcam", "handoff", (1, 1), ok=False)
    assert closure_reference(steps, 5) is None  # navcam tracks and the designation (~10 m) are never one


def test_the_reference_order_can_be_asked_for():
    steps = [_step("pancam", "designate", (1, 0)), _step("pancam", "track", (1, 1)), _step("navcam", "handoff", (1, 1)),
             _step("navcam", "track", (1, 2)), _step("navcam", "track", (1, 3)),
             _step("hazcam", "handoff", (1, 3), final=True)]
    assert closure_reference(steps, 5, CLOSURE_REFERENCES) == closure_reference(steps, 5) == 1
    assert closure_reference(steps, 5, (("navcam", "handoff"), ("pancam", "track"))) == 2
    assert closure_reference(steps, 5, (("pancam", "designate"),)) == 0  # a measurement may ask for the designation
    assert closure_reference(steps, 5, (("navcam", "track"),)) == 3  # the last one before the final stop
    assert closure_reference(steps, 5, (("hazcam", "handoff"),)) is None


def test_closure_params_and_record():
    with pytest.raises(ValueError, match="closure"):
        ChainParams(closure="yes").check()
    d = Closure("no reference").to_dict()
    assert d["status"] == "no reference" and d["uv"] is None and d["closure_px"] is None
    assert Closure("confirmed", closure_px=float("nan")).to_dict()["closure_px"] is None
    assert d["feature_pooled"] is None and Closure("confirmed", feature_refine_px=float("nan")).to_dict()[
        "feature_refine_px"] is None


def test_visual_odometry_in_the_closure_by_default():
    """ChainParams.closure_vo (on by default since session 18): the closure's feature step also has the
    visual-odometry candidate (the drive's pose error from the reference's image to the whole final hazcam image,
    pipeline/feature_track.py vo_correction) and records its inliers and whether it won; off, the closure records
    nothing of it. The default chain's final answers on paper-s1-straight are held to their bounds by test_chain.py
    (chain_expected.py EXPECTED_FINAL_PX, measured with it on)."""
    from pathlib import Path

    from scipctl.io.downlink import read_downlink
    from scipctl.pipeline.chain import run_chain

    with pytest.raises(ValueError, match="closure_vo"):
        ChainParams(closure_vo=1).check()
    assert ChainParams().closure_vo is True and Closure("confirmed").to_dict()["vo_inliers"] is None
    dl = read_downlink(Path(__file__).resolve().parents[2] / "sample_sols" / "mcap" / "paper-s1-straight.mcap")
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = dl.target("t2").mark_in(start.product_id)
    feats = {}
    on = run_chain(dl, start, [mk.u, mk.v], target_id="t2", feature_cache=feats)[-1].extra["closure"]
    assert on["vo_inliers"] is not None and on["vo_inliers"] >= ChainParams().vo_min_inliers
    assert isinstance(on["feature_vo"], bool)
    # a confirmed closure records its own consistency (the closure model's log_refine, log_pooled): how many
    # candidates agreed, and how far NCC moved the winner from its feature position, which confirmation bounds
    assert on["status"] == "confirmed" and on["feature_pooled"] >= 1
    assert 0.0 <= on["feature_refine_px"] <= ChainParams().feature_confirm_px
    off = run_chain(dl, start, [mk.u, mk.v], target_id="t2", feature_cache=feats,
                    params=ChainParams(closure_vo=False))[-1].extra["closure"]
    assert off["vo_inliers"] is None and off["feature_vo"] is None


def _standin_stop(pan_width=1024):
    """A navcam and a pancam on one mast at one stop (stand-ins: only what pancam_from_navcam reads), the same
    rover pose estimate, and a target ~4.5 m ahead in the rover frame."""
    from types import SimpleNamespace

    from scipctl.core.transforms import RigidTransform, axis_angle_to_matrix
    from tests.models import cahv, cahvor

    T_site_rover = RigidTransform(axis_angle_to_matrix([0, 0, 1], 0.7), np.array([10.0, -4.0, 0.2]))
    pose = SimpleNamespace(T_site_rover=T_site_rover)
    nav = SimpleNamespace(product_id="nav-L", camera_model=cahvor(f_px=400.0, tilt_down_rad=0.3), pose=pose,
                          width=1024, height=1024, time_s=5.0)
    pan = SimpleNamespace(product_id="pan-L", camera_model=cahv(f_px=1200.0, tilt_down_rad=0.3, C=(0.42, 0.15, -1.5)),
                          pose=pose, width=pan_width, height=1024, time_s=6.0)
    X_rover = nav.camera_model.C + 4.5 * nav.camera_model.A + np.array([0.0, 0.05, 0.0])

    class DL:
        def images_at(self, position, camera=None, eye=None):
            return [pan] if camera == "pancam" else [nav]

        def product(self, pid):
            return {"nav-L": nav, "pan-L": pan}[pid]

    return DL(), nav, pan, X_rover


def test_pancam_from_navcam_projects_the_navcam_point_into_the_pancam():
    from scipctl.pipeline.chain_closure import pancam_from_navcam

    dl, nav, pan, X_rover = _standin_stop()
    T = nav.pose.T_site_rover
    uv_nav = nav.camera_model.project(X_rover[None])[0]
    N = _step("navcam", "handoff", (1, 1), uv=uv_nav, xyz=T.apply(X_rover))
    N.product_id = "nav-L"
    R = pancam_from_navcam(dl, N)
    # exact pixel and point: the pancam's own projection of the target (no drive between the two images)
    assert R.camera == "pancam" and R.product_id == "pan-L" and R.position == N.position
    np.testing.assert_allclose(R.tracked_uv, pan.camera_model.project(X_rover[None])[0], atol=1e-9)
    np.testing.assert_allclose(R.xyz_site_m, T.apply(X_rover), atol=1e-9)
    # a stereo point off its pixel's ray (range error) is moved onto the ray first
    N.xyz_site_m = list(T.apply(X_rover + np.array([0.0, 0.3, 0.1])))
    R = pancam_from_navcam(dl, N)
    o, d = nav.camera_model.unproject(np.asarray(uv_nav, float)[None])
    X = T.inverse().apply(np.asarray(R.xyz_site_m))
    assert np.linalg.norm(np.cross(X - o[0], d[0])) < 1e-9
    np.testing.assert_allclose(R.tracked_uv, pan.camera_model.project(X[None])[0], atol=1e-9)
    # nothing to start from: a point outside the pancam image, or no point
    dl_narrow, *_ = _standin_stop(pan_width=100)
    N.xyz_site_m = list(T.apply(X_rover))
    assert pancam_from_navcam(dl_narrow, N) is None
    N.xyz_site_m = None
    assert pancam_from_navcam(dl, N) is None


def test_the_pancam_from_navcam_option_is_checked():
    with pytest.raises(ValueError, match="closure_pancam_from_navcam"):
        ChainParams(closure_pancam_from_navcam=1).check()
    assert ChainParams().closure_pancam_from_navcam is False


def test_reference_lineage_follows_each_steps_reference_back_to_the_designation():
    from scipctl.pipeline.chain import ChainStep
    from scipctl.pipeline.chain_closure import reference_lineage

    def st(pid, ref=None, kind="track"):
        return ChainStep((1, 0), "pancam", pid, kind, None, None, None, None, None, None, None, None, None, True,
                         extra={} if ref is None else {"reference": ref})

    # d -> p1 -> p2 (p3 unverified: skipped as a reference) -> p4; n1 a navcam handoff from p2
    steps = [st("d", kind="designate"), st("p1", "d"), st("p2", "p1"), st("p3", "p2"), st("n1", "p2", "handoff"),
             st("p4", "p2")]
    assert reference_lineage(steps, 5) == [5, 2, 1]
    assert reference_lineage(steps, 4) == [4, 2, 1]
    assert reference_lineage(steps, 1) == [1]
    assert reference_lineage(steps, 0) == [] and reference_lineage(steps, None) == [] and \
        reference_lineage(steps, 6) == []
    # a reference that names no step of the chain ends the lineage; a loop does not hang it
    assert reference_lineage([st("d", kind="designate"), st("a", "elsewhere"), st("b", "a")], 2) == [2, 1]
    assert reference_lineage([st("d", kind="designate"), st("a", "b"), st("b", "a")], 2) == [2, 1]


def test_closure_evidence_multiplies_the_step_p_along_the_reference_lineage():
    from scipctl.pipeline.chain import ChainStep
    from scipctl.pipeline.chain_closure import closure_evidence

    def st(pid, ref, p):
        return ChainStep((1, 0), "pancam", pid, "track", None, None, None, None, None, None, None, None, None, True,
                         extra={"reference": ref}, p_success=p)

    steps = [ChainStep((1, 0), "pancam", "d", "designate", None, None, None, None, None, None, None, None, None,
                       True, p_success=0.99),
             st("p1", "d", 0.9), st("p2", "p1", 0.5), st("n1", "p1", 0.2), st("p3", "p2", 0.8)]
    ev = closure_evidence(steps, {"reference_step": 4})
    assert ev.path_p == pytest.approx(0.9 * 0.5 * 0.8, rel=1e-15)  # n1 is not on p3's lineage; d not a track
    assert ev.ref_p_success == 0.8
    steps[2].p_success = None  # a step on the lineage unscored: the path's p is unknown
    assert math.isnan(closure_evidence(steps, {"reference_step": 4}).path_p)
    assert math.isnan(closure_evidence(steps, {}).path_p)
