"""pipeline/feature_track.py's visual odometry (vo_correction and the chain's ChainParams.vo_cameras option) on the
bundled sols; the numerics are tested on exact synthetic scenes in tests/core/test_visual_odometry.py."""

from pathlib import Path

import numpy as np
import pytest

from scipctl.io.downlink import read_downlink
from scipctl.pipeline.chain import ChainParams, run_chain
from scipctl.pipeline.feature_track import vo_correction
from scipctl.pipeline.plane_warp import near_dense_stereo

SOLS = sorted((Path(__file__).resolve().parents[2] / "sample_sols" / "mcap").glob("paper-s1-*.mcap"))


@pytest.fixture(scope="module", params=SOLS, ids=lambda p: p.stem)
def dl(request):
    return read_downlink(request.param)


def _navcams(dl):
    return sorted((im for im in dl.images if im.camera == "navcam" and im.eye == "left"), key=lambda i: i.time_s)


def test_visual_odometry_corrects_the_drive_between_the_first_two_navcam_stops(dl):
    """From the 4.5 m navcam to the 3 m one (a 1.5 m drive): the pose correction from the whole image (>= 500 RANSAC
    inliers; measured 704-823 on OpenCV 5.0 and 4.14) puts each marked target's stereo point (the 4.5 m image's dense
    stereo at its mark) within 5.5 px of its 3 m mark, where the pose estimate puts it 30-85 px away. Measured
    0.32-4.34 px (OpenCV 5.0.0) and 0.32-3.64 px (4.14.0) over the five targets of the two sols (/tmp/vo_sample.py
    of session 17); bound = the largest x 1.25, rounded up to 0.5 px. The error is the stereo point's and the fit's."""
    a, b = _navcams(dl)[:2]
    params = ChainParams()
    seen = 0
    for t in dl.targets:
        ma, mb = t.mark_in(a.product_id), t.mark_in(b.product_id)
        if ma is None or mb is None:
            continue
        X_a = near_dense_stereo(dl, a, 4.5).xyz_at_left_uv(np.array([[ma.u, ma.v]]))
        rng = float(np.linalg.norm(X_a[0] - a.camera_model.C))
        X_a = near_dense_stereo(dl, a, rng).xyz_at_left_uv(np.array([[ma.u, ma.v]]))
        corr = vo_correction(dl, a, b, rng, {}, params)
        assert corr is not None and corr.n_inliers >= 500
        X_b = b.pose.T_site_rover.inverse().apply(a.pose.T_site_rover.apply(X_a))
        pose_err = np.linalg.norm(b.camera_model.project(X_b)[0] - [mb.u, mb.v])
        vo_err = np.linalg.norm(b.camera_model.project(corr.apply(X_b))[0] - [mb.u, mb.v])
        assert pose_err > 25.0
        assert vo_err < 5.5, f"{t.id}: {vo_err:.2f} px (pose estimate {pose_err:.1f} px)"
        seen += 1
    assert seen >= 2


def test_visual_odometry_shares_the_feature_steps_keypoint_cache(dl):
    """The whole images' keypoints go into the feature step's cache under its keys (product, 1.0, median), their
    2-NN matches under ("knn", prev, new, median): a second call finds them there, and a second call handed the
    previous image's stereo, as the chain and the closure hand it, gives the same correction bit for bit."""
    a, b = _navcams(dl)[:2]
    params = ChainParams()
    feats = {}
    c1 = vo_correction(dl, a, b, 4.5, feats, params)
    m = params.feature_median_px
    assert set(feats) == {(a.product_id, 1.0, m), (b.product_id, 1.0, m), ("knn", a.product_id, b.product_id, m)}
    c2 = vo_correction(dl, a, b, 4.5, feats, params)
    c3 = vo_correction(dl, a, b, 4.5, {}, params, near_dense_stereo(dl, a, 4.5))
    for c in (c2, c3):
        assert np.array_equal(c1.R_camtrue_camest, c.R_camtrue_camest)
        assert np.array_equal(c1.t_camtrue_camest_m, c.t_camtrue_camest_m)


def test_a_caller_whose_stereo_failed_gets_no_odometry_and_no_second_stereo(dl, monkeypatch):
    """prev_stereo=None is the caller's failed stereo: vo_correction answers None without running stereo again."""
    import scipctl.pipeline.plane_warp as plane_warp

    a, b = _navcams(dl)[:2]
    calls = []
    monkeypatch.setattr(plane_warp, "near_dense_stereo", lambda *args, **kw: calls.append(args))
    assert vo_correction(dl, a, b, 4.5, {}, ChainParams(), None) is None
    assert calls == []


@pytest.mark.parametrize("field, bad", [("vo_cameras", "navcam"), ("vo_cameras", (1,)), ("vo_threshold_px", 0.0),
                                        ("vo_threshold_px", float("nan")), ("vo_min_inliers", 5),
                                        ("vo_min_inliers", 20.0), ("vo_ratio", 0.0), ("vo_ratio", 1.5)])
def test_chain_params_refuse_bad_vo_settings(field, bad):
    with pytest.raises(ValueError, match=f"ChainParams.{field}"):
        ChainParams(**{field: bad}).check()
    assert ChainParams(vo_cameras=("navcam",)).check()


_CHAINS: dict = {}


# what the NCC peak of a feature step decides (status, candidates, the winner's peak, the feature evidence the trust
# models read): a placement option must leave these bit for bit and move only the answer
_DECIDED = ("feature_status", "feature_confirmed", "feature_pooled", "feature_candidates", "ncc_uv", "ncc_score",
            "coarse_uv", "feature_shift_px", "feature_inliers", "feature_local_inliers")


def _first_target_chain(dl, **fields):
    """``run_chain`` of the sol's first target from its first pancam mark, answer "handoff" (every step tracked),
    with these ``ChainParams`` fields; each run once per module (the options' tests compare against the same
    default chain)."""
    key = (dl.source, repr(sorted(fields.items())))
    if key not in _CHAINS:
        start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
        tid = dl.targets[0].id
        mk = dl.target(tid).mark_in(start.product_id)
        _CHAINS[key] = run_chain(dl, start, [mk.u, mk.v], target_id=tid, params=ChainParams(answer="handoff", **fields))
    return _CHAINS[key]


def test_visual_odometry_is_an_option_of_the_navcam_tracks(dl):
    """Off by default (no track records it; the handoff across a drive has its own odometry, ChainParams.vo_handoff,
    on by default since session 31); with vo_cameras=("navcam",) every navcam track records whether the winning
    candidate was the odometry's (feature_vo), and where the fit held, its inliers and how far it moved the
    prediction; the pancam steps and the handoff to the navcam are untouched (same pixels bit for bit)."""
    assert ChainParams().vo_cameras == ()
    if Path(dl.source).stem != "paper-s1-straight":
        pytest.skip("one sol is enough (two whole chains, ~40 s)")
    base = _first_target_chain(dl)
    assert not any("feature_vo" in s.extra or "vo_inliers" in s.extra for s in base if s.kind == "track")
    params = ChainParams(answer="handoff", vo_cameras=("navcam",))
    steps = _first_target_chain(dl, vo_cameras=("navcam",))
    assert [(s.camera, s.kind) for s in steps[:3]] == [(s.camera, s.kind) for s in base[:3]]
    for s, s0 in zip(steps[:3], base[:3]):
        assert s.tracked_uv == s0.tracked_uv
    tracks = [s for s in steps if s.camera == "navcam" and s.kind == "track" and s.extra.get("coarse") == "features"]
    assert tracks
    for s in tracks:
        if s.extra.get("feature_status") in ("confirmed", "unconfirmed"):
            assert isinstance(s.extra["feature_vo"], bool)
        if "vo_inliers" in s.extra:
            assert s.extra["vo_inliers"] >= params.vo_min_inliers and s.extra["vo_shift_px"] >= 0.0
    assert any("vo_inliers" in s.extra for s in tracks)


def _without_imaging_stop_pancam(dl):
    """``dl`` without the pancam images of the approach's imaging stop (the second pancam stop): the chain then
    hands the target from the ~10 m designation straight to that stop's navcam, across the drive, as it does when
    its pancam track there is not trusted. ``(start pancam, that downlink, the imaging stop's left navcam)``."""
    import dataclasses

    pancams = sorted((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    start, mid = pancams[0], pancams[1]
    nav = next(im for im in _navcams(dl) if im.position == mid.position)
    return start, dataclasses.replace(dl, images=[im for im in dl.images
                                                  if not (im.camera == "pancam" and im.position == mid.position)]), nav


def _designation(dl, start, mark, params):
    """The chain's designation of ``mark`` in ``start``: its point stereo (range, m) and its point on the pixel's ray,
    site frame ``(3,)``, as run_chain keeps it."""
    from scipctl.core.point_stereo import on_left_ray
    from scipctl.pipeline.chain import stereo_at

    uv = np.array([mark.u, mark.v])
    ps = stereo_at(dl, start, uv, params)
    assert ps is not None and ps.ok
    return float(ps.range_m), start.pose.T_site_rover.apply(on_left_ray(start.camera_model, uv, ps.xyz))


def test_visual_odometry_across_the_drive_from_the_designation_to_the_navcam(dl):
    """From the ~10 m pancam to the imaging stop's navcam (two cameras, one drive): the whole-image correction
    (>= 100 RANSAC inliers; measured 201-212) puts each marked target's designation (the pancam's point stereo at
    its mark) within 3 px of its navcam mark, where the pose estimate puts it 80-225 px away. Measured 0.69-1.25 px
    (OpenCV 5.0.0) and 0.51-1.62 px (4.14.0) over the five targets of the two sols (/tmp/vo_only.py of session 30);
    bound = the largest x ~1.85, rounded to 0.5 px: the error is the designation's stereo and the fit's."""
    start, _, mid_nav = _without_imaging_stop_pancam(dl)
    params = ChainParams()
    seen = 0
    for t in dl.targets:
        m0, m1 = t.mark_in(start.product_id), t.mark_in(mid_nav.product_id)
        if m0 is None or m1 is None:
            continue
        rng, X_site = _designation(dl, start, m0, params)
        X_nav = mid_nav.pose.T_site_rover.inverse().apply(X_site)
        corr = vo_correction(dl, start, mid_nav, rng, {}, params)
        assert corr is not None and corr.n_inliers >= 100
        pose_err = np.linalg.norm(mid_nav.camera_model.project(X_nav[None])[0] - [m1.u, m1.v])
        vo_err = np.linalg.norm(mid_nav.camera_model.project(corr.apply(X_nav[None]))[0] - [m1.u, m1.v])
        assert vo_err < 3.0, f"{t.id}: {vo_err:.2f} px (pose estimate {pose_err:.1f} px)"
        assert pose_err > 3 * vo_err
        seen += 1
    assert seen >= 2


def test_visual_odometry_matches_the_two_images_resolutions_only_when_they_differ_by_half_an_octave(dl):
    """vo_correction(new_range_m=...): MER's 10 m pancam and 4.5 m navcam differ by ~1.3x on the ground (under
    feature_track.VO_SCALE_MATCH_MIN), so the correction and the cache are those of the call without it, bit for bit;
    told a range that makes the navcam's pixel 2x the pancam's on the ground, the pancam's keypoints are detected at
    half resolution (cached under that factor, the 2-NN under both factors) and the correction still holds (>= 20
    inliers)."""
    from scipctl.pipeline.feature_track import VO_SCALE_MATCH_MIN

    start, _, nav = _without_imaging_stop_pancam(dl)
    params = ChainParams()
    t = next(t for t in dl.targets if t.mark_in(start.product_id) is not None)
    rng, X_site = _designation(dl, start, t.mark_in(start.product_id), params)
    rng_nav = float(np.linalg.norm(nav.pose.T_site_rover.inverse().apply(X_site) - nav.camera_model.C))
    ratio = (rng_nav / nav.camera_model.hs) / (rng / start.camera_model.hs)
    assert 1.0 < ratio < VO_SCALE_MATCH_MIN
    f0, f1 = {}, {}
    c0 = vo_correction(dl, start, nav, rng, f0, params)
    c1 = vo_correction(dl, start, nav, rng, f1, params, new_range_m=rng_nav)
    assert set(f0) == set(f1)
    assert np.array_equal(c0.R_camtrue_camest, c1.R_camtrue_camest)
    assert np.array_equal(c0.t_camtrue_camest_m, c1.t_camtrue_camest_m)
    f2 = {}
    c2 = vo_correction(dl, start, nav, rng, f2, params, new_range_m=rng_nav * 2.0 / ratio)
    m = params.feature_median_px
    assert any(len(k) == 3 and k[0] == start.product_id and abs(k[1] - 2.0) < 1e-9 and k[2] == m for k in f2)
    assert any(len(k) == 6 and k[0] == "knn" and abs(k[4] - 2.0) < 1e-9 and k[5] == 1.0 for k in f2)
    assert c2 is not None and c2.n_inliers >= params.vo_min_inliers


def test_visual_odometry_is_an_option_of_the_cross_drive_handoff(dl):
    """ChainParams.vo_handoff: off, the chain's handoff from the designation to the imaging stop's navcam records
    no odometry; on (the default since session 31), it records whether the odometry's candidate won (feature_vo)
    and its inliers, and its pixel stays confirmed within 2.5 px of the mark (measured for paper-s1-straight t1:
    0.12 px on OpenCV 5.0, 0.25 px on 4.14; the bound is the handoff's own, the designation's stereo and one navcam
    NCC peak); the designation is the same."""
    if Path(dl.source).stem != "paper-s1-straight":
        pytest.skip("one sol is enough (two whole chains)")
    start, dl2, _ = _without_imaging_stop_pancam(dl)
    tid = dl.targets[0].id
    mk = dl.target(tid).mark_in(start.product_id)
    runs = {on: run_chain(dl2, start, [mk.u, mk.v], target_id=tid, params=ChainParams(answer="handoff", vo_handoff=on))
            for on in (False, True)}
    assert ChainParams().vo_handoff is True
    off, on = runs[False][1], runs[True][1]
    for s in (off, on):
        assert (s.camera, s.kind, s.extra["reference"]) == ("navcam", "handoff", start.product_id)
    assert "vo_inliers" not in off.extra and "feature_vo" not in off.extra
    assert isinstance(on.extra["feature_vo"], bool) and on.extra["vo_inliers"] >= ChainParams().vo_min_inliers
    assert on.extra["feature_status"] == "confirmed" and on.ok and on.error_px < 2.5
    assert runs[True][0].tracked_uv == runs[False][0].tracked_uv
    with pytest.raises(ValueError, match="ChainParams.vo_handoff"):
        ChainParams(vo_handoff=1).check()


def _first_pancam_track(dl, tid, params):
    """The chain's first pancam track (10 m -> 4.5 m) of target ``tid``, as run_chain sets it up: (TrackResult or
    None, info, the 4.5 m mark)."""
    from scipctl.core.point_stereo import on_left_ray
    from scipctl.core.windows import window_scale_for_handoff
    from scipctl.pipeline.chain import stereo_at
    from scipctl.pipeline.feature_track import feature_track
    from scipctl.pipeline.plane_warp import local_normals_site

    pancams = sorted((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    start, prod = pancams[0], pancams[1]
    m0, m1 = dl.target(tid).mark_in(start.product_id), dl.target(tid).mark_in(prod.product_id)
    uv = np.array([m0.u, m0.v])
    ps = stereo_at(dl, start, uv, params)
    X_site = start.pose.T_site_rover.apply(on_left_ray(start.camera_model, uv, ps.xyz))
    X_rover = prod.pose.T_site_rover.inverse().apply(X_site)
    pred = prod.camera_model.project(X_rover[None])[0]
    rng_new = float(np.linalg.norm(X_rover - prod.camera_model.C))
    scale = window_scale_for_handoff(1.0 / start.camera_model.hs, float(ps.range_m), 1.0 / prod.camera_model.hs, rng_new)
    stereo = near_dense_stereo(dl, start, float(ps.range_m))
    normal, ground = local_normals_site(start, start.pose.T_site_rover.inverse().apply(X_site), float(ps.range_m), stereo)
    planes = [normal] + ([ground] if np.degrees(np.arccos(np.clip(ground @ normal, -1, 1))) > 5.0 else [])
    tr, info = feature_track(start, prod, X_site, planes, normal, pred, scale, params.template_half("pancam"), {},
                             params)
    return tr, info, np.array([m1.u, m1.v])


@pytest.mark.parametrize("tid", ["t2", "t3"])
def test_matched_blur_is_an_option_that_raises_the_ncc_of_a_coarser_template(dl, tid):
    """ChainParams.ncc_matched_blur (off by default; measured on whole chains and not adopted: docs/stereo-and-
    tracking.md, "Matched blur"): the 4.5 m image is blurred to the 10 m template's resolution before NCC. Where the
    step is confirmed both ways (both sols' t3, paper-s1-straight's t2) the peak NCC rises (measured +0.045 to
    +0.254 on OpenCV 5.0.0, +0.033 to +0.266 on 4.14.0) and the pixel stays on the mark (measured 0.42-1.25 px |
    0.30-1.44 px; bound 2 px, as EXPECTED_ERROR_PX's pancam bound of t2)."""
    from dataclasses import replace

    assert ChainParams().ncc_matched_blur is False
    if Path(dl.source).stem == "paper-s1-arc" and tid == "t2":
        pytest.skip("paper-s1-arc marks no t2 in its 4.5 m pancam image")
    off, info_off, mark = _first_pancam_track(dl, tid, ChainParams())
    on, info_on, _ = _first_pancam_track(dl, tid, replace(ChainParams(), ncc_matched_blur=True))
    assert info_off["feature_status"] == info_on["feature_status"] == "confirmed"
    assert on.score > off.score
    assert np.linalg.norm(on.uv - mark) <= 2.0


def test_matched_blur_flag_must_be_a_bool():
    """ChainParams.check() names the field when ncc_matched_blur is not true/false (a 0/1 from a config file would
    otherwise switch the option silently)."""
    from dataclasses import replace

    with pytest.raises(ValueError, match="ncc_matched_blur"):
        replace(ChainParams(), ncc_matched_blur=1).check()
    assert replace(ChainParams(), ncc_matched_blur=True, ncc_place_flow=()).check().ncc_matched_blur is True


def test_render_antialias_flag_must_be_a_bool():
    """ChainParams.check() names the field when render_antialias is not true/false."""
    from dataclasses import replace

    with pytest.raises(ValueError, match="render_antialias"):
        replace(ChainParams(), render_antialias="yes").check()
    assert replace(ChainParams(), render_antialias=True).check().render_antialias is True


def test_texture_retry_sigma_must_be_a_positive_number_or_none():
    """ChainParams.check() names the field; None (the default) turns the retry off."""
    from dataclasses import replace

    assert ChainParams().texture_retry_sigma_px is None
    for bad in (0.0, -3.0, float("nan"), "8", True):
        with pytest.raises(ValueError, match="texture_retry_sigma_px"):
            replace(ChainParams(), texture_retry_sigma_px=bad).check()
    assert replace(ChainParams(), texture_retry_sigma_px=8.0).check().texture_retry_sigma_px == 8.0


def test_texture_view_is_the_same_product_with_its_lighting_taken_out(dl):
    """texture_view: the product's geometry unchanged, its pixels core/illumination.log_highpass of its own, under
    another product id (a keypoint cache keyed by product id keeps the two apart); the original is untouched."""
    from scipctl.core.illumination import log_highpass
    from scipctl.pipeline.feature_track import texture_view

    im = _navcams(dl)[0]
    before = im.pixels.copy()
    tv = texture_view(im, 6.0)
    assert tv.product_id == im.product_id + "#texture6" and tv.camera_model is im.camera_model and tv.pose is im.pose
    # pixels_float() of the view is the filtered image over 255: the NCC and SIFT's percentile stretch do not see
    # the factor (exact: the same float32 array divided once)
    assert np.array_equal(tv.pixels_float(), log_highpass(im.pixels_float(), 6.0) / np.float32(255.0))
    assert np.array_equal(im.pixels, before)


# ----------------------------------------------------------------------------- the two-stage NCC (ncc_place_half_px)
def _relief_template(dy_px: int, half: int = 15, place_half: int = 7):
    """A smooth random image (seeded) and a template of it whose central ``(2 place_half + 1)`` square is the image
    at the target (100, 90) and whose surroundings are drawn ``dy_px`` rows off: what a plane template shows when
    the ground around a rock stands off the rock top's plane."""
    import cv2

    rng = np.random.default_rng(5)
    img = cv2.GaussianBlur(rng.normal(size=(200, 200)).astype(np.float32), (0, 0), 1.5)
    ii, jj = np.mgrid[-half:half + 1, -half:half + 1]
    outer = np.maximum(abs(ii), abs(jj)) > place_half
    return img, img[90 + ii + np.where(outer, dy_px, 0), 100 + jj]


@pytest.mark.parametrize("dy_px", [1, 2, 3])
def test_the_centre_places_what_the_whole_template_found(dy_px):
    """The whole template's NCC peak is pulled towards where its surroundings match (0.74-2.50 px off for 1-3 rows,
    measured); the central 15 px crop, searched within 2 px of that peak, puts the target back where its own pixels
    match exactly: within 0.02 px (an exact match at an integer position; the sub-pixel fit leaves 0.0034 px,
    measured, bound 6x that). The score stays the whole template's (what the trust models were fitted on)."""
    from scipctl.core.tracking import track
    from scipctl.pipeline.feature_track import place_with_centre

    img, tpl = _relief_template(dy_px)
    found = track(tpl, img, np.array([103.0, 93.0]), 10.0, min_score=0.3, accept_border_peak=False)
    assert found.ok and np.linalg.norm(found.uv - [100, 90]) > 0.5
    placed = place_with_centre(found, tpl, img, np.array([15.0, 15.0]), 7, 2.0)
    assert np.linalg.norm(placed.uv - [100, 90]) < 0.02
    assert placed.score == found.score and placed.second_score == found.second_score


def test_the_centre_keeps_the_found_answer_when_it_cannot_place_it():
    """A failed match, a crop no smaller than the template, or a crop whose peak lies on the border of its search
    (the truth beyond the radius) give the found answer back unchanged."""
    import dataclasses

    from scipctl.core.tracking import track
    from scipctl.pipeline.feature_track import place_with_centre

    img, tpl = _relief_template(3)
    found = track(tpl, img, np.array([103.0, 93.0]), 10.0, min_score=0.3, accept_border_peak=False)
    centre = np.array([15.0, 15.0])
    failed = dataclasses.replace(found, ok=False)
    assert place_with_centre(failed, tpl, img, centre, 7, 2.0) is failed
    assert place_with_centre(found, tpl, img, centre, 15, 2.0) is found
    assert np.linalg.norm(found.uv - [100, 90]) > 2.0  # 2.50 px: beyond a 1 px search
    assert place_with_centre(found, tpl, img, centre, 7, 1.0) is found


@pytest.mark.parametrize("value", [{"navcam": 15}, {"navcam": 0}, {"navcam": 7.0}, {"navcam": True}, "navcam",
                                   {"pancam": 20}])
def test_chain_params_refuse_a_bad_placing_crop(value):
    with pytest.raises(ValueError, match="ChainParams.ncc_place_half_px"):
        ChainParams(ncc_place_half_px=value).check()


@pytest.mark.parametrize("other", [{"ncc_median_prev_px": 1.0}, {"ncc_matched_blur": True}])
def test_chain_params_refuse_a_placing_crop_with_a_filtered_ncc(other):
    """The placement runs on the unfiltered image; with the median or the matched blur it would be skipped silently,
    so the pair is refused."""
    with pytest.raises(ValueError, match="ChainParams.ncc_place_half_px: places on the unfiltered image only"):
        ChainParams(ncc_place_half_px={"navcam": 7}, ncc_place_flow=(), **other).check()
    assert ChainParams(ncc_place_flow=(), **other).check()


@pytest.mark.parametrize("radius", [0.0, -1.0, float("nan"), True])
def test_chain_params_refuse_a_bad_placing_radius(radius):
    with pytest.raises(ValueError, match="ChainParams.ncc_place_radius_px"):
        ChainParams(ncc_place_radius_px=radius).check()


def test_the_two_stage_ncc_is_an_option_of_the_navcam_tracks(dl):
    """Off by default; with ncc_place_half_px={"navcam": 7} (and the navcam's default flow placement off: one
    placement per camera) the pancam steps are the same bit for bit as without either, and the first step that
    differs is a feature step into a navcam image (here the handoff from the pancam). The whole template
    still decides that step: its status, how many candidates were confirmed and pooled, the winner's NCC peak and
    feature position and the pose shift (the trust models' evidence) are the one-stage step's, bit for bit; only the
    answer moves, by at most the placing radius (each pooled candidate's placed pixel lies within the radius of its
    peak, and the answer is their weighted mean with the one-stage weights)."""
    assert ChainParams().ncc_place_half_px == {}
    assert ChainParams(ncc_place_half_px={"navcam": 7}, ncc_place_flow=()).check()
    if Path(dl.source).stem != "paper-s1-straight":
        pytest.skip("one sol is enough (two whole chains)")
    base = _first_target_chain(dl, ncc_place_flow=())
    params = ChainParams(answer="handoff", ncc_place_half_px={"navcam": 7}, ncc_place_flow=())
    steps = _first_target_chain(dl, ncc_place_half_px={"navcam": 7}, ncc_place_flow=())
    diff = [(s, s0) for s, s0 in zip(steps, base) if s.tracked_uv != s0.tracked_uv]
    assert diff and all(s.tracked_uv == s0.tracked_uv for s, s0 in zip(steps, base) if s.camera == "pancam")
    s, s0 = diff[0]
    assert s.camera == "navcam" and s.extra.get("coarse") == "features"
    assert s.extra["feature_status"] == "confirmed" and "ncc_placed_uv" not in s0.extra
    assert {k: s.extra.get(k) for k in _DECIDED} == {k: s0.extra.get(k) for k in _DECIDED}
    assert np.linalg.norm(np.subtract(s.extra["ncc_placed_uv"], s.extra["ncc_uv"])) <= params.ncc_place_radius_px
    assert np.linalg.norm(np.subtract(s.tracked_uv, s0.tracked_uv)) <= params.ncc_place_radius_px


# ----------------------------------------------------------------------------- optical-flow placement (ncc_place_flow)
@pytest.mark.parametrize("value", ["pancam", ("pancam", 3), {"pancam": 1}, None])
def test_chain_params_refuse_a_bad_flow_placement(value):
    with pytest.raises(ValueError, match="ChainParams.ncc_place_flow"):
        ChainParams(ncc_place_flow=value).check()


@pytest.mark.parametrize("other", [{"ncc_median_prev_px": 1.0}, {"ncc_matched_blur": True},
                                   {"ncc_place_half_px": {"pancam": 7}}])
def test_chain_params_refuse_a_flow_placement_with_a_filtered_ncc_or_a_second_placement(other):
    """The flow runs on the unfiltered image (with the median or the matched blur it would be skipped silently),
    and one camera's answer has one placement."""
    with pytest.raises(ValueError, match="ChainParams.ncc_place_flow"):
        ChainParams(ncc_place_flow=("pancam",), **other).check()
    assert ChainParams(ncc_place_flow=("navcam",), ncc_place_half_px={"pancam": 7}).check()


@pytest.mark.parametrize("other", [{"ncc_median_prev_px": 1.0}, {"ncc_matched_blur": True}])
def test_a_filtered_ncc_is_refused_with_the_default_flow_and_says_how_to_turn_it_off(other):
    """The navcam's flow placement is on by default (session 52), so the filtered NCCs (measured and not adopted)
    run with ncc_place_flow=() only; the refusal says so."""
    with pytest.raises(ValueError, match=r"ChainParams.ncc_place_flow: .*\('navcam',\).*ncc_place_flow=\(\) turns it off"):
        ChainParams(**other).check()
    assert ChainParams(ncc_place_flow=(), **other).check()


def test_the_flow_placement_moves_only_the_answer_of_the_cameras_named(dl):
    """With ncc_place_flow=("pancam",) the first step that differs from the chain without the flow is the first
    pancam track (a feature step; t2 of the straight sol, whose first pancam track the features confirm): its
    status, confirmed and pooled candidates, the winner's NCC peak, feature position and pose shift (the trust
    models' evidence) are those without the flow, bit for bit; the winner's placed pixel is recorded and only the
    answer moves. The steps before it are the same."""
    if Path(dl.source).stem != "paper-s1-straight":
        pytest.skip("one sol is enough (two whole chains)")
    start = min((im for im in dl.images if im.camera == "pancam" and im.eye == "left"), key=lambda i: i.time_s)
    mk = dl.target("t2").mark_in(start.product_id)
    base, steps = (run_chain(dl, start, [mk.u, mk.v], target_id="t2", params=ChainParams(answer="handoff", **f))
                   for f in ({"ncc_place_flow": ()}, {"ncc_place_flow": ("pancam",)}))
    first = next(i for i, (s, s0) in enumerate(zip(steps, base)) if s.tracked_uv != s0.tracked_uv)
    s, s0 = steps[first], base[first]
    assert all(a.tracked_uv == b.tracked_uv for a, b in zip(steps[:first], base[:first]))
    assert s.camera == "pancam" and s.kind == "track" and s.extra.get("coarse") == "features"
    assert s.extra["feature_status"] == "confirmed" and "ncc_placed_uv" not in s0.extra
    assert {k: s.extra.get(k) for k in _DECIDED} == {k: s0.extra.get(k) for k in _DECIDED}
    assert s.extra["ncc_placed_uv"] != s.extra["ncc_uv"]


def test_the_flow_places_the_navcam_by_default_and_moves_only_its_answers(dl):
    """The default places the navcam's feature steps by the flow (adopted in session 52, docs/stereo-and-tracking.md
    "Optical flow places the cross-drive navcam handoff"). Against the chain without it (t1 of the straight sol,
    whose first pancam track fails and whose handoff across the drive is a confirmed feature step): the steps
    before the first navcam step are the same, and that step keeps what the NCC peak decided (status, candidates,
    the winner's peak and feature evidence) bit for bit; every navcam feature step (the later ones start from the
    moved answers, so their evidence moves too) records its winner's placed pixel and answers otherwise than
    without the flow (the answer pools the confirmed candidates' placed pixels); no other camera's
    step records a placed pixel."""
    assert ChainParams().ncc_place_flow == ("navcam",)
    if Path(dl.source).stem != "paper-s1-straight":
        pytest.skip("one sol is enough (two whole chains)")
    base, steps = _first_target_chain(dl, ncc_place_flow=()), _first_target_chain(dl)  # t1, the sol's first target
    first = next(i for i, (s, s0) in enumerate(zip(steps, base)) if s.tracked_uv != s0.tracked_uv)
    assert steps[first].camera == "navcam" and steps[first].kind == "handoff"
    assert all(a.tracked_uv == b.tracked_uv for a, b in zip(steps[:first], base[:first]))
    navcam_features = [i for i, s in enumerate(base) if s.camera == "navcam" and s.extra.get("coarse") == "features"]
    assert first in navcam_features and len(navcam_features) == 3
    s, s0 = steps[first], base[first]
    assert {k: s.extra.get(k) for k in _DECIDED} == {k: s0.extra.get(k) for k in _DECIDED}
    for i in navcam_features:
        s, s0 = steps[i], base[i]
        assert s.extra["feature_status"] == "confirmed" and "ncc_placed_uv" not in s0.extra
        assert s.extra["ncc_placed_uv"] != s.extra["ncc_uv"]
        assert s.tracked_uv != s0.tracked_uv
    assert not any("ncc_placed_uv" in s.extra for s in steps if s.camera != "navcam")
