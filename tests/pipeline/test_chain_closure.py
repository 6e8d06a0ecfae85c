"""The closure check's reference choice (pipeline/chain_closure.py); its run on real chains is in test_chain.py."""

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
