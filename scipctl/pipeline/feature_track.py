"""The chain's feature-guided step (pipeline/chain.py; the closure check, pipeline/chain_closure.py, uses it too):
the previous view rendered into the new one through a plane, SIFT features matched against the whole new image,
a RANSAC model for the pose error, NCC to refine (docs/stereo-and-tracking.md, "Tracking through the stops")."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..jsonutil import finite_or_none as _f
from ..model import ImageProduct
from ..core.flow_place import flow_place
from ..core.matched_blur import blurred_crop, footprint_cov, gaussian_kernel
from ..core.windows import filtered_crop, median_image
from .plane_warp import (plane_points_site, plane_warped_view, prev_pixels_through_plane, render_through_plane,
                         render_through_surface)


# ChainParams.ncc_median_find: how far (new pixels) the unfiltered NCC may move the median-filtered NCC's peak
MEDIAN_FIND_PLACE_PX = 2.0
# vo_correction with the new image's range: when one image's pixel covers at least this many times the other's on the
# ground at the target, the finer image's keypoints are detected on it downsampled by that ratio (Mars 2020's Mastcam-Z
# at 10 m against its navcam at 4.5 m: ~3x; MER's pancam against its navcam: ~1.3x, left as it is)
VO_SCALE_MATCH_MIN = 1.5


@dataclasses.dataclass
class _Candidate:
    """One candidate of :func:`feature_track`: a coarse position and the NCC that refined it. ``loc``: the
    :class:`~scipctl.core.features.FeatureLocation` (feature match or visual odometry; its ``uv`` in new pixels);
    ``track``: the :class:`~scipctl.core.tracking.TrackResult` of the template around it (its peak decides
    confirmation, pooling and the trust evidence); ``plane``: index of its view normal; ``reach``: its keypoint
    reach (0: the visual-odometry candidate); ``factor``: the feature step factor it was found at;
    ``relief_kept``: the fraction of the template the relief mask kept (None: no mask); ``masked``: whether the
    mask was applied; ``place_uv``: the pixel it answers with (the peak, or the peak placed by the template's
    centre, ``ChainParams.ncc_place_half_px``, or by the optical flow, ``ChainParams.ncc_place_flow``)."""

    loc: object
    track: object
    plane: int
    reach: float
    factor: float
    relief_kept: object
    masked: bool
    place_uv: np.ndarray


def feature_track(prev: ImageProduct, prod: ImageProduct, X_site, view_normals, n_site, pred_uv, scale: float,
                  half: int, feats: dict, params, new_stereo=None, vo=None, surface=None):
    """Track the target from ``prev`` into ``prod`` guided by features; ``(TrackResult or None, info dict)``.

    For each plane normal in ``view_normals`` (site frame, planes through
    ``X_site``), ``prev``'s image is rendered into ``prod``'s view around the
    prediction ``pred_uv`` (:func:`plane_warped_view`) at ``prev``'s own
    resolution (one rendered pixel per ``scale`` new pixels, ``scale`` = new
    pixels per previous pixel at the target, at least 1), so that scale and
    perspective changes are taken out by the geometry and what is left is the
    pose-estimate error (a shift and a small rotation). Its SIFT keypoints
    near the target are matched against those of the whole new image
    (area-downsampled by the same factor, so that both have the same blur; both median-filtered,
    ``params.feature_median_px``, so that grains only the nearer view resolves make no keypoints) and
    a homography ``G`` (pose-estimate pixels of ``prod`` -> real pixels) is
    fitted by RANSAC, with keypoints from a few reaches and models (``params.feature_candidates``)
    around the target. For each ``G``, the template (half-size ``half``) is
    rendered through the target's plane ``n_site`` at the pixels ``G^-1``
    maps the new image's to, so that it carries the rotation of the pose
    error too, and NCC-tracked within ``params.feature_fine_radius_px`` of the mapped
    prediction; the best NCC wins. With ``new_stereo`` (``prod``'s
    :class:`~scipctl.core.dense_stereo.DenseStereo`) and ``params.relief_max_parallax_px`` set, the NCC counts
    only the template pixels the plane places where that stereo says they are (:mod:`scipctl.core.relief_mask`;
    all of them when fewer than ``params.relief_min_kept`` of the template would be left). ``feats`` caches the
    new images' keypoints by ``(product id, downsampling)`` (the chains of one downlink may share it: same image, same downsampling, same
    keypoints). ``vo``: a :class:`~scipctl.core.visual_odometry.CameraCorrection` of ``prod`` (whole-image visual
    odometry, :func:`vo_correction`) or None: when given, it is one more candidate after the features', its
    coarse position the target seen through it and its ``G`` the plane's homography under it, NCC-refined and
    confirmed like the others. ``surface``: ``prev``'s
    :class:`~scipctl.core.dense_stereo.DenseStereo` (its rover frame) or None: when given, the NCC templates are drawn
    through the surface it measured (``params.template_surface_gate_px`` / ``template_surface_level``;
    :func:`~scipctl.pipeline.plane_warp.render_through_surface`; the feature views stay the plane's). ``info`` records the path, the winner's inlier counts and the coarse position.
    """
    from ..core.features import detect_features, knn_matches, locate_by_features
    from ..core.relief_mask import relief_keep
    from ..core.tracking import TrackResult, track

    info = {"coarse": "features", "feature_inliers": 0, "feature_local_inliers": 0}
    relief = new_stereo is not None and params.relief_max_parallax_px is not None
    if relief:
        T_roverprev_rovernew = prev.pose.T_site_rover.inverse() @ prod.pose.T_site_rover
        T_rovernew_site = prod.pose.T_site_rover.inverse()
        # the relief mask's reference pixels: the template's centre (the target's own surface), a quarter of its size
        gg = np.abs(np.stack(np.meshgrid(np.arange(-half, half + 1), np.arange(-half, half + 1)), -1)).max(-1)
        centre = (gg <= max(1, half // 4)).reshape(-1)
    img = prod.pixels_float()
    median_px = None
    if params.ncc_median_prev_px is not None:
        # the median's width in new pixels: previous-image pixels x the zoom, the nearest odd size, at least 3
        median_px = max(3, 2 * int(round((params.ncc_median_prev_px * max(float(scale), 1.0) - 1) / 2)) + 1)
    g = np.arange(-half, half + 1, dtype=float)
    c = np.round(np.asarray(pred_uv, float))
    cands, seen, reasons = [], [], []
    closest = None  # (inliers, matches, what was tried): the failed keypoint match that came nearest a model

    def refine(loc, Gi, k, reach, factor):
        """NCC of the template rendered at the pixels ``Gi`` (real pixels of prod -> pose-estimate pixels) maps prod's
        pixels around ``loc.uv`` to; appended to ``cands`` unless the rendering misses the previous view."""
        cc = np.round(loc.uv)
        xs = np.stack(np.meshgrid(cc[0] + g, cc[1] + g), -1).reshape(-1, 2)
        yh = np.c_[xs, np.ones(len(xs))] @ Gi.T
        with np.errstate(divide="ignore", invalid="ignore"):
            ys = yh[:, :2] / yh[:, 2:3]
        grid = ys.reshape(2 * half + 1, 2 * half + 1, 2)
        if surface is None:
            tpl = render_through_plane(prev, prod, X_site, n_site, grid, params.render_antialias)
        else:
            tpl = render_through_surface(prev, prod, X_site, n_site, surface, grid, params.template_surface_gate_px,
                                         params.template_surface_level, params.render_antialias)
        if np.isfinite(tpl).mean() < 0.9:
            return
        keep, kept = None, None
        if relief:
            # the template's pixels are prod's pixels xs: the plane's points on their rays (pose estimate)
            X_on = T_rovernew_site.apply(plane_points_site(prod, X_site, n_site, xs))
            on_plane = relief_keep(new_stereo, xs, X_on, T_roverprev_rovernew, prev.camera_model, centre,
                                   params.relief_disparity_error_px, params.relief_max_parallax_px,
                                   other_px_scale=max(float(scale), 1e-6))
            on_plane = on_plane.reshape(tpl.shape) & np.isfinite(tpl)
            kept = float(on_plane.mean())
            if kept >= params.relief_min_kept and not on_plane.all():
                keep = on_plane
        tpl = np.where(np.isfinite(tpl), tpl, np.nanmean(tpl)).astype(np.float32)
        kernel = None
        if params.ncc_matched_blur and np.all(np.isfinite(loc.uv)):
            kernel = _matched_blur_kernel(prev, prod, X_site, n_site, ys, half)
        crop = None
        crop_reach = int(math.ceil(params.feature_fine_radius_px)) + half + 2  # (``reach`` is the candidate's)
        if kernel is not None:
            # None when the search region lies wholly outside the image (the plain track below says so)
            crop, o = blurred_crop(img, loc.uv, crop_reach, kernel)
        elif median_px is not None and np.all(np.isfinite(loc.uv)):
            raw_tpl = tpl
            tpl = median_image(tpl, median_px)
            crop, o = filtered_crop(img, loc.uv, crop_reach, median_px, lambda a: median_image(a, median_px))
        if crop is None:
            # a whole rendered window: a peak where it touches the image's edge confirms nothing
            tr = track(tpl, img, loc.uv, params.feature_fine_radius_px, template_center_uv=loc.uv - (cc - half),
                       min_score=0.3, accept_border_peak=False, template_mask=keep)
        else:
            tr = track(tpl, crop, loc.uv - o, params.feature_fine_radius_px, template_center_uv=loc.uv - (cc - half),
                       min_score=0.3, accept_border_peak=False, template_mask=keep)
            tr = dataclasses.replace(tr, uv=tr.uv + o)
            if median_px is not None and params.ncc_median_find and tr.ok:
                # the median found the peak; the unfiltered NCC places it and scores it (what the trust models know)
                raw = track(raw_tpl, img, tr.uv, MEDIAN_FIND_PLACE_PX, template_center_uv=loc.uv - (cc - half),
                            min_score=0.3, accept_border_peak=False, template_mask=keep)
                if raw.ok and np.all(np.isfinite(raw.uv)):
                    tr = raw
        # the pixel this candidate answers with: its NCC peak, or that peak placed by the template's centre (the
        # second stage; the peak itself still decides confirmation, pooling and the trust evidence)
        place_uv = tr.uv
        place_half = params.ncc_place_half_px.get(prod.camera)
        if place_half is not None and crop is None:  # (no filtered crop: ChainParams.check refuses the two together)
            place_uv = place_with_centre(tr, tpl, img, loc.uv - (cc - half), place_half, params.ncc_place_radius_px,
                                         keep).uv
        elif prod.camera in params.ncc_place_flow and crop is None and tr.ok:
            flowed = flow_place(tpl, img, tr.uv, loc.uv - (cc - half))
            if flowed is not None:
                place_uv = flowed
        cands.append(_Candidate(loc, tr, k, reach, factor, kept, keep is not None, place_uv))

    def confirmed(cd):
        tr = cd.track
        return tr.ok and np.all(np.isfinite(tr.uv)) and np.linalg.norm(tr.uv - cd.loc.uv) <= params.feature_confirm_px

    for factor in params.feature_step_factors:
        if any(confirmed(cd) for cd in cands):
            break  # a coarser rendering only when nothing was confirmed at the finer one
        step_px = float(np.clip(scale * factor, 1.0, 4.0 * factor))
        vhalf = int(round(params.view_reach_px / step_px))
        # exact: a cache shared by chains gives each the keypoints it would compute
        key = (prod.product_id, step_px, params.feature_median_px)
        if key not in feats:
            feats[key] = detect_features(prod.pixels_float(), downsample=step_px, median_px=params.feature_median_px)
        # pose-estimate pixels of prod -> rendering pixels
        S = np.array([[1 / step_px, 0, vhalf - c[0] / step_px], [0, 1 / step_px, vhalf - c[1] / step_px],
                      [0, 0, 1.0]])
        for k, n_view in enumerate(view_normals):
            view, vc = plane_warped_view(prev, prod, X_site, n_view, pred_uv, vhalf, step_px=step_px,
                                         antialias=params.render_antialias)
            if np.isfinite(view).mean() < 0.2:
                reasons.append(f"plane {k}: the previous view does not cover the prediction")
                continue
            ref = detect_features(view, median_px=params.feature_median_px)
            # the keypoints within the largest reach, matched once: each candidate takes its reach's rows
            reach_max = max(cand[0] for cand in params.feature_candidates)
            if len(ref):
                ref = ref.subset(np.linalg.norm(ref.uv - vc, axis=1) <= reach_max * vhalf)
            knn = knn_matches(ref, feats[key])
            for reach, model, min_inliers in params.feature_candidates:
                loc = locate_by_features(ref, vc, feats[key], ref_radius_px=reach * vhalf, model=model,
                                         ransac_threshold_px=2.0 * step_px, min_inliers=min_inliers,
                                         local_radius_px=params.feature_local_px / step_px, knn=knn)
                if not loc.ok:
                    reasons.append(f"x{factor:g} plane {k} reach {reach:g}: {loc.reason}")
                    if closest is None or (loc.n_inliers, loc.n_matches) > closest[:2]:
                        closest = (loc.n_inliers, loc.n_matches, reasons[-1])
                    continue
                if any(np.linalg.norm(loc.uv - q) < 1.0 for q in seen):
                    continue
                seen.append(loc.uv)
                try:
                    Gi = np.linalg.inv(loc.transform @ S)
                except np.linalg.LinAlgError:
                    continue
                refine(loc, Gi, k, reach, factor)
    if vo is not None:
        vo_loc = _vo_location(prod, X_site, n_site, pred_uv, half, vo, params.feature_local_px)
        if vo_loc is not None:
            info["vo_inliers"], info["vo_shift_px"] = vo.n_inliers, float(np.linalg.norm(vo_loc.uv - pred_uv))
            if not any(np.linalg.norm(vo_loc.uv - q) < 1.0 for q in seen):
                refine(vo_loc, np.linalg.inv(vo_loc.transform), 0, 0.0, 1.0)
    if not cands:
        info["feature_status"] = "failed"
        info["feature_tries"] = list(reasons)
        info["feature_reason"] = failure_summary(reasons, None if closest is None else closest[2])
        return None, info
    # Several candidates (planes, reaches, resolutions) measure the same position. A candidate is confirmed when
    # NCC refines it to a peak near its feature match. The answer pools the candidates instead of taking the
    # single best, so that which candidate scores a hair higher does not move the answer by their spread:
    # confirmed -> the score-weighted mean of the confirmed NCC positions within params.feature_agree_px of the best one;
    # none confirmed -> the inlier-weighted geometric median of the feature matches (reported as such).
    good = [cd for cd in cands if confirmed(cd)]
    if good:
        best = max(good, key=lambda cd: (cd.track.score, -cd.plane, cd.reach, cd.factor))
        near = [cd for cd in good if np.linalg.norm(cd.track.uv - best.track.uv) <= params.feature_agree_px]
        w = np.array([max(cd.track.score, 1e-3) for cd in near])
        found_uv = (w[:, None] * np.array([cd.track.uv for cd in near])).sum(0) / w.sum()
        uv = (w[:, None] * np.array([cd.place_uv for cd in near])).sum(0) / w.sum()
        winner = best
        info["feature_status"] = "confirmed"
        info["feature_pooled"] = len(near)
        bt = best.track
        out = TrackResult(True, "", uv, bt.score, bt.second_score, bt.ratio, bt.sharpness, bt.levels)
    else:
        pts = np.array([cd.loc.uv for cd in cands])
        w = np.array([max(cd.loc.n_inliers, 1) for cd in cands], float)
        uv = found_uv = geometric_median(pts, w)
        winner = min(cands, key=lambda cd: (np.linalg.norm(cd.loc.uv - uv), -cd.loc.n_inliers))
        info["feature_status"] = "unconfirmed"
        info["feature_pooled"] = len(cands)
        # the NCC peak found elsewhere is not this position's score: recorded in info only
        out = TrackResult(True, "", uv, float("nan"), float("nan"), float("nan"), float("nan"), 0)
    loc, tr = winner.loc, winner.track
    info.update({"feature_inliers": loc.n_inliers, "feature_local_inliers": loc.n_local_inliers,
                 "feature_matches": loc.n_matches, "feature_reach": winner.reach, "feature_plane": winner.plane,
                 "feature_candidates": len(cands), "feature_confirmed": len(good),
                 "feature_step_factor": winner.factor,
                 **({"feature_vo": bool(winner.reach == 0.0)} if vo is not None else {}),
                 "feature_shift_px": float(np.linalg.norm(found_uv - pred_uv)), "coarse_uv": loc.uv.tolist(),
                 "ncc_uv": tr.uv.tolist() if np.all(np.isfinite(tr.uv)) else None, "ncc_score": _f(tr.score)})
    if (prod.camera in params.ncc_place_half_px or prod.camera in params.ncc_place_flow) and good:
        info["ncc_placed_uv"] = best.place_uv.tolist() if np.all(np.isfinite(best.place_uv)) else None
    if relief:
        info.update({"relief_kept": _f(winner.relief_kept), "relief_masked": winner.masked})
    return out, info


def failure_summary(tries: list, closest) -> str:
    """One clause for a feature step that found no model: ``tries`` (each try's "x<view> plane <k> reach <r>:
    <why>", in the order tried) and ``closest`` (of the tries that matched keypoints, the one nearest a model: most
    RANSAC inliers, then matches; None when no try got that far, e.g. every view missed the prediction). A single
    try, or none with a ``closest``, is said as it is; more read "no feature model in N tries; closest: <that try>"
    (the whole list is the step's ``feature_tries``)."""
    if not tries:
        return "no usable feature model"
    if len(tries) == 1 or closest is None:
        return "; ".join(tries)
    return f"no feature model in {len(tries)} tries; closest: {closest}"


def place_with_centre(found, template, image, centre_in_template_uv, place_half: int, radius_px: float, mask=None):
    """The second stage of a two-stage NCC (``ChainParams.ncc_place_half_px``): ``found`` (a
    :class:`~scipctl.core.tracking.TrackResult` of ``template`` in ``image``) moved to where the template's central
    ``(2 place_half + 1)`` square crop peaks, NCC within ``radius_px`` of ``found.uv``; its score and shape stay the
    whole template's. ``found`` unchanged when it failed, when the crop's match fails or peaks on the search border,
    or when the crop would not be smaller than the template.

    ``template`` ``(2 h + 1, 2 h + 1)`` with the tracked point at ``centre_in_template_uv`` (template pixels, within
    half a pixel of its centre ``(h, h)``); ``mask`` ``None`` or bool of the template's shape (the pixels NCC
    counts), cropped alike.
    """
    from ..core.tracking import track

    h = (template.shape[0] - 1) // 2
    if template.shape != (2 * h + 1, 2 * h + 1):
        raise ValueError(f"template: expected a square of odd size, got shape {template.shape}")
    if not found.ok or not np.all(np.isfinite(found.uv)) or not 1 <= place_half < h:
        return found
    box = (slice(h - place_half, h + place_half + 1),) * 2
    centre = np.asarray(centre_in_template_uv, float) - (h - place_half)
    placed = track(template[box], image, found.uv, float(radius_px), template_center_uv=centre, min_score=0.3,
                   accept_border_peak=False, template_mask=None if mask is None else mask[box])
    if not placed.ok or not np.all(np.isfinite(placed.uv)):
        return found
    return dataclasses.replace(found, uv=placed.uv)


def texture_view(im: ImageProduct, sigma_px: float) -> ImageProduct:
    """A copy of ``im`` whose pixels are its texture without its lighting (:func:`scipctl.core.illumination.log_highpass`
    of its own, float32; ``pixels_float()`` divides them by 255, which neither NCC nor SIFT's percentile stretch sees),
    under its product id with ``#texture<sigma_px>`` appended so that a keypoint cache keeps the two apart."""
    from ..core.illumination import log_highpass

    return dataclasses.replace(im, product_id=f"{im.product_id}#texture{sigma_px:g}",
                               _pixels=log_highpass(im.pixels_float(), sigma_px))


def _matched_blur_kernel(prev: ImageProduct, prod: ImageProduct, X_site, n_site, ys, half: int):
    """The kernel that blurs ``prod`` to the resolution of a template rendered from ``prev`` through the plane
    (X_site, n_site) (core/matched_blur.py), or None. ``ys`` ((2 half + 1)^2, 2): the pose-estimate pixels of the
    template's grid, whose real pixels are one apart; the map's Jacobian is taken by central differences at its
    centre."""
    n = 2 * half + 1
    centre = ys.reshape(n, n, 2)[half - 1:half + 2, half - 1:half + 2].reshape(-1, 2)
    P = prev_pixels_through_plane(prev, prod, X_site, n_site, centre).reshape(3, 3, 2)
    J_prev_new = np.stack([(P[1, 2] - P[1, 0]) / 2.0, (P[2, 1] - P[0, 1]) / 2.0], axis=1)
    cov = footprint_cov(J_prev_new)
    return None if cov is None else gaussian_kernel(cov, max_sigma_px=half / 3.0)


def confirmed_consistency(info: dict) -> tuple[float, float]:
    """``(pooled, refine_px)`` of a :func:`feature_track` ``info`` (as recorded on a chain step or read by the
    closure): how many candidates' NCC positions agreed and were pooled, and how far NCC moved the winning candidate
    from its feature position (px of the new image). Both NaN unless the step was confirmed (an unconfirmed step's
    NCC peak is elsewhere) or without the positions recorded. The step and closure trust models' ``pooled`` and
    ``refine_px``."""
    if info.get("feature_status") != "confirmed":
        return math.nan, math.nan
    pooled = info.get("feature_pooled")
    a, b = info.get("coarse_uv"), info.get("ncc_uv")
    return (math.nan if pooled is None else float(pooled),
            math.nan if a is None or b is None else float(np.linalg.norm(np.subtract(b, a))))


def _vo_location(prod: ImageProduct, X_site, n_site, pred_uv, half: int, vo, local_px: float):
    """The visual-odometry candidate: a :class:`~scipctl.core.features.FeatureLocation` at the target seen through
    ``vo``, whose ``transform`` maps ``prod``'s pose-estimate pixels to its real ones for the target's plane (the
    homography of the plane's points around the prediction, pose estimate -> through ``vo``); None when the
    target or the plane is not in front of the camera."""
    import cv2

    from ..core.features import FeatureLocation

    T_rovernew_site = prod.pose.T_site_rover.inverse()
    uv = prod.camera_model.project(vo.apply(T_rovernew_site.apply(np.asarray(X_site, float)[None])))[0]
    r = 2.0 * half
    grid = np.asarray(pred_uv, float) + np.array([[i, j] for i in (-r, 0.0, r) for j in (-r, 0.0, r)])
    P_site = plane_points_site(prod, X_site, n_site, grid)
    real = prod.camera_model.project(vo.apply(T_rovernew_site.apply(P_site)))
    ok = np.all(np.isfinite(real), 1) & np.all(np.isfinite(P_site), 1)
    if not np.all(np.isfinite(uv)) or ok.sum() < 4:
        return None
    G, _ = cv2.findHomography(grid[ok], real[ok], 0)
    if G is None or not np.all(np.isfinite(G)):
        return None
    local = int(np.sum(np.linalg.norm(vo.inlier_uv - uv, axis=1) <= local_px))
    return FeatureLocation(True, "", uv, G, vo.n_points, vo.n_inliers, local, float("nan"))


def vo_correction(dl, prev: ImageProduct, prod: ImageProduct, prev_range_m: float, feats: dict, params,
                  prev_stereo=..., new_range_m=None):
    """Whole-image visual odometry of ``prod`` from ``prev`` (:mod:`scipctl.core.visual_odometry`): SIFT keypoints of
    both whole images (full resolution, median-filtered as the feature step's; cached in ``feats`` under the
    feature step's keys), matched (2-NN ratio ``params.vo_ratio``), ``prev``'s matched keypoints placed in 3-D by
    its dense stereo around the target's range (:func:`~scipctl.pipeline.plane_warp.near_dense_stereo`) and
    carried into ``prod``'s rover frame through the two pose estimates; then
    :func:`~scipctl.core.visual_odometry.camera_correction`. None when stereo or the fit fails. ``prev_stereo``:
    ``near_dense_stereo(dl, prev, prev_range_m)`` when the caller has it, None included (its stereo failed: no
    odometry, and no second try); left out (``...``): computed here. The whole images'
    2-NN matches depend on the two images only: cached in ``feats`` under ``("knn", prev, prod, median)``, so the
    targets of one downlink share them. ``new_range_m`` (the target's range from ``prod``'s camera, m; None: not
    used): when the two images' pixels differ on the ground at the target by :data:`VO_SCALE_MATCH_MIN` or more, the
    finer image's keypoints are detected at the coarser one's resolution (``detect_features``' ``downsample``, cached
    under that factor; the 2-NN under ``("knn", prev, prod, median, prev factor, new factor)``) and a downsampled
    new image's RANSAC threshold grows by its factor."""
    from ..core.features import detect_features, knn_matches
    from ..core.visual_odometry import camera_correction
    from .plane_warp import near_dense_stereo

    ds = near_dense_stereo(dl, prev, prev_range_m) if prev_stereo is ... else prev_stereo
    if ds is None:
        return None
    d_prev = d_new = 1.0
    if new_range_m is not None:
        # new-image pixels per previous-image pixel on the ground at the target (> 1: the new image is the coarser)
        ratio = (float(new_range_m) / prod.camera_model.hs) / (float(prev_range_m) / prev.camera_model.hs)
        if ratio >= VO_SCALE_MATCH_MIN:
            d_prev = ratio
        elif 1.0 / ratio >= VO_SCALE_MATCH_MIN:
            d_new = 1.0 / ratio
    kps = []
    for im, d in ((prev, d_prev), (prod, d_new)):
        key = (im.product_id, d, params.feature_median_px)
        if key not in feats:
            feats[key] = detect_features(im.pixels_float(), downsample=d, median_px=params.feature_median_px)
        kps.append(feats[key])
    f_prev, f_new = kps
    if len(f_prev) < 2 or len(f_new) < 2:
        return None
    key = ("knn", prev.product_id, prod.product_id, params.feature_median_px)
    if (d_prev, d_new) != (1.0, 1.0):
        key = key + (d_prev, d_new)
    if key not in feats:
        feats[key] = knn_matches(f_prev, f_new)
    knn = feats[key]
    good = np.isfinite(knn.best_d) & (knn.best_d < params.vo_ratio * knn.second_d)
    X_roverprev = ds.xyz_at_left_uv(f_prev.uv[good])
    fin = np.all(np.isfinite(X_roverprev), 1)
    X_rovernew = prod.pose.T_site_rover.inverse().apply(prev.pose.T_site_rover.apply(X_roverprev[fin]))
    uv_new = f_new.uv[knn.best[good]][fin]
    return camera_correction(X_rovernew, uv_new, prod.camera_model, params.vo_threshold_px * d_new,
                             params.vo_min_inliers)


def geometric_median(points, weights, iterations: int = 100, tol_px: float = 1e-6) -> np.ndarray:
    """Weighted geometric median of ``points`` ``(N, 2)`` (Weiszfeld's iteration from the weighted mean).

    The point minimising ``sum w_i |x - p_i|``: one far-off point moves it
    by little, and it moves continuously with the points (a robust pooling
    of candidate positions).
    """
    p = np.asarray(points, float)
    w = np.asarray(weights, float)
    if p.ndim != 2 or p.shape[1] != 2 or w.shape != (len(p),) or len(p) == 0:
        raise ValueError(f"points (N, 2) and weights (N,) expected, got {p.shape} and {w.shape}")
    x = (w[:, None] * p).sum(0) / w.sum()
    for _ in range(iterations):
        d = np.linalg.norm(p - x, axis=1)
        if np.any(d < 1e-12):
            return p[int(np.argmin(d))].copy()
        x_new = ((w / d)[:, None] * p).sum(0) / (w / d).sum()
        if np.linalg.norm(x_new - x) < tol_px:
            return x_new
        x = x_new
    return x
