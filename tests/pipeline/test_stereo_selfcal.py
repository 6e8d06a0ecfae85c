"""pipeline/stereo_selfcal.py on the bundled rendered downlink: each pair's fitted right-eye turn against the render's
exact truth (its true camera models), and what the copy changes and keeps."""

from pathlib import Path

import numpy as np
import pytest

from scipctl.core.camera import T_model_cam
from scipctl.core.transforms import matrix_to_rotvec
from scipctl.io.downlink import read_downlink
from scipctl.pipeline.stereo_selfcal import self_calibrate_downlink

SAMPLE = Path(__file__).resolve().parents[2] / "sample_sols" / "mcap" / "paper-s1-straight.mcap"


@pytest.fixture(scope="module")
def calibrated():
    dl = read_downlink(SAMPLE)
    models = {im.product_id: im.camera_model for im in dl.images}
    out, pairs = self_calibrate_downlink(dl)
    return dl, models, out, pairs


def _true_turn(dl, left_id, right_id):
    """The right eye's turn relative to the left eye's, in the downlinked rover frame: each eye's rotation from its
    downlinked model to its true one (mast and pose errors turn both eyes alike and cancel)."""
    L, R = dl.product(left_id), dl.product(right_id)
    R_true_est_left = T_model_cam(dl.truth_for(left_id).camera_model).R @ T_model_cam(L.camera_model).R.T
    R_true_est_right = T_model_cam(dl.truth_for(right_id).camera_model).R @ T_model_cam(R.camera_model).R.T
    return matrix_to_rotvec(R_true_est_left.T @ R_true_est_right)


def test_every_pair_recovers_its_true_rows_and_roll(calibrated):
    dl, _, _, pairs = calibrated
    assert {p.camera for p in pairs} == {"pancam", "navcam", "hazcam"} and len(pairs) == 6
    for p in pairs:
        assert p.fit.ok and p.applied, p.fit.reason
        m = dl.product(p.right_product_id).camera_model
        w = _true_turn(dl, p.left_product_id, p.right_product_id)
        rows_true = w @ (m.h_axis / np.linalg.norm(m.h_axis)) * m.hs
        roll_true = w @ m.A * m.hs
        # bounds: the largest errors measured on the 42 pairs of seven errors-double downlinks (seeds 1534, 1551,
        # ..., 1636: turns twice this sample's, up to 7.3 px), rows 0.30 px and roll 0.41 px when the fit was built
        # (session 56); today's fit there: rows <= 0.273, roll <= 0.266 (session 58); here <= 0.021 and <= 0.076
        assert abs(p.fit.rows_px - rows_true) <= 0.30, p
        assert abs(p.fit.roll_px - roll_true) <= 0.41, p
        # the pair is epipolar-consistent afterwards: the matches' median residual is their position noise. Measured
        # 0.057-0.097 px here and 0.049-0.110 px on the 42 errors-double pairs; the fits are bit for bit the same
        # with OpenCV's threads at 1, 2 and 4 and OpenBLAS's at 1 and 2 (OpenCV 5.0.0, session 57), and on all 48
        # pairs with the OpenCV builds 4.11.0, 4.14.0 and 5.0.0 (session 58, /work/scratch/s58/ana/selfcal_builds.py):
        # margin 0.04 px over the largest
        assert p.fit.residual_px_after <= 0.15


def test_the_copy_changes_right_models_only(calibrated):
    dl, models, out, pairs = calibrated
    assert [im.camera_model for im in dl.images] == [models[im.product_id] for im in dl.images]  # given: unchanged
    right_ids = {p.right_product_id for p in pairs if p.applied}
    for im in out.images:
        if im.product_id in right_ids:
            assert not im.camera_model.almost_equal(models[im.product_id], tol=1e-12)
            np.testing.assert_allclose(im.camera_model.C, models[im.product_id].C, atol=1e-12)
        else:
            assert im.camera_model is models[im.product_id]
    assert out.truth_images is dl.truth_images and out.targets is dl.targets


def test_records_are_json_ready(calibrated):
    import json

    _, _, _, pairs = calibrated
    d = json.loads(json.dumps([p.to_dict() for p in pairs]))
    assert d[0]["left"].endswith("-L") and d[0]["applied"] is True and len(d[0]["rotvec_rad"]) == 3


def test_a_pair_without_texture_keeps_its_model():
    """A right image with nothing to match (flat grey): the fit is refused with its reason, the model stays."""
    from dataclasses import replace

    dl = read_downlink(SAMPLE)
    left = next(im for im in dl.images if im.camera == "hazcam" and im.eye == "left")
    right = dl.stereo_pair(left)
    flat = replace(right, _pixels=np.full((right.height, right.width), 900, np.uint16))
    one_pair = replace(dl, images=[left, flat])
    out, pairs = self_calibrate_downlink(one_pair)
    assert len(pairs) == 1 and not pairs[0].applied and not pairs[0].fit.ok
    assert "fewer than" in pairs[0].fit.reason
    assert out.images[1].camera_model is right.camera_model


def test_only_the_chosen_pairs_are_fitted_and_each_fit_is_its_pair_alone(calibrated):
    """``only`` (what a command reads): the rejected pairs are neither fitted nor changed, and a chosen pair's new
    model is bit for bit the one the all-pairs run gives (a pair's fit reads that pair alone), so a command that
    fits fewer pairs answers as a campaign that fits them all."""
    dl, models, out_all, _ = calibrated
    out, pairs = self_calibrate_downlink(dl, only=lambda im: im.camera in ("navcam", "hazcam"))
    assert {p.camera for p in pairs} == {"navcam", "hazcam"} and len(pairs) == 4
    fitted = {p.right_product_id for p in pairs}
    for im, im_all in zip(out.images, out_all.images):
        if im.product_id in fitted:
            assert im.camera_model.almost_equal(im_all.camera_model, tol=0)
        else:
            assert im.camera_model is models[im.product_id]
    _, none = self_calibrate_downlink(dl, only=lambda im: False)
    assert none == []


def test_known_fits_are_taken_and_give_the_same_models(calibrated, monkeypatch):
    """A pair whose key is known takes the known fit (nothing is matched again) and its model is bit for bit the
    one fitting gives; every pair then carries its key, ``cached`` only the known ones."""
    import scipctl.pipeline.stereo_selfcal as mod

    dl, _, out_all, pairs_all = calibrated
    hazcam = lambda im: im.camera == "hazcam"  # noqa: E731 (one pair: the test fits it once more)
    out1, (p1,) = self_calibrate_downlink(dl, only=hazcam, known={})
    assert len(p1.key) == 64 and not p1.cached
    fit_all = next(p.fit for p in pairs_all if p.right_product_id == p1.right_product_id)
    assert p1.fit.to_dict() == fit_all.to_dict()  # fitting again: the same fit

    def refuse(*_a, **_k):
        raise AssertionError("a known pair was matched again")

    monkeypatch.setattr(mod, "stereo_matches", refuse)
    out2, (p2,) = self_calibrate_downlink(dl, only=hazcam, known={p1.key: p1.fit})
    assert p2.cached and p2.key == p1.key and p2.to_dict() == p1.to_dict()  # the record of the fit made
    right = out_all.product(p1.right_product_id).camera_model
    assert out2.product(p1.right_product_id).camera_model.to_dict() == right.to_dict()
    with pytest.raises(AssertionError, match="matched again"):  # an unknown key is fitted
        self_calibrate_downlink(dl, only=hazcam, known={"0" * 64: p1.fit})


def test_a_pair_key_changes_with_anything_the_fit_reads():
    """The key is the fit's inputs: one pixel, the right model, a parameter or the code changes it."""
    from dataclasses import replace

    import scipctl.pipeline.stereo_selfcal as mod
    from scipctl.core.stereo_selfcal import StereoSelfCalParams, rotated_model
    from scipctl.pipeline.stereo_selfcal import pair_key

    dl = read_downlink(SAMPLE)
    left = next(im for im in dl.images if im.camera == "navcam" and im.eye == "left")
    right = dl.stereo_pair(left)
    params = StereoSelfCalParams()
    key = pair_key(left, right, params)
    assert pair_key(read_downlink(SAMPLE).product(left.product_id), right, params) == key  # read again: the same
    px = right.pixels.copy()
    px[500, 500] ^= 1
    assert pair_key(left, replace(right, _pixels=px), params) != key
    turned = replace(right, camera_model=rotated_model(right.camera_model, [1e-9, 0.0, 0.0]))
    assert pair_key(left, turned, params) != key
    assert pair_key(left, right, replace(params, ratio=0.79)) != key
    assert pair_key(right, left, params) != key
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(mod, "fit_code_identity", lambda: "other code")
        assert pair_key(left, right, params) != key
