"""Track a designated target through the stops of an approach (SCIP steps 3 and 5) and hand it
from pancam to navcam, then to the hazcams.

At each rover position (time order) the target's 3-D estimate (site frame,
through the rover's pose estimates) predicts where it appears in the new left
image. The pose estimates can be degrees off in yaw, so the prediction can be
hundreds of pixels off: the previous stop's image is rendered into the new
view through the local surface plane (which takes out the change of scale and
perspective), SIFT features of the rendering are matched against the whole
new image and a RANSAC model maps the target's place in the rendering into it
(the coarse position); a template rendered through that model is then
NCC-tracked within ``FEATURE_FINE_RADIUS_PX`` of it. When no feature model is
found, the older NCC path (a large context window over the search region) gives
an answer that is reported as unverified. At the same stop, the pancam window
is shrunk by the IFOV ratio and tracked into the navcam image (the paper's
handoff). Stereo at the tracked pixel updates the 3-D estimate. Every step
records in ``extra`` which path found it, the feature inlier counts and the
coarse position; a weak or unverified step has ``ok=False`` and is not used as
the reference for the next stop.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..model import Downlink, ImageProduct, InputError
from ..jsonutil import finite_or_none

TEMPLATE_HALF_PX = {"pancam": 20, "navcam": 15, "hazcam": 15}
# pointing error from the pose estimate: pancam IFOV is 1/3 of navcam's, so it needs 3x the radius in pixels
SEARCH_RADIUS_PX = {"pancam": 300.0, "navcam": 100.0, "hazcam": 80.0}
# fallback when no feature match is found: half-size of the NCC context window that first finds the pose error,
# and the target search radius after it
CONTEXT_HALF_PX = {"pancam": 100, "navcam": 60, "hazcam": 60}
FINE_RADIUS_PX = 20.0
# feature-guided step (_feature_track): the previous view rendered into the new view covers +-VIEW_REACH_PX new
# pixels around the prediction
VIEW_REACH_PX = 300
# the rendering's pixel = this many previous-image pixels (1: its own resolution); the coarser one is tried when
# nothing was confirmed at the finer one (smooth 10 m sand against the 4.5 m image's fine speckle)
FEATURE_STEP_FACTORS = (1.0, 1.5)
# candidates: (keypoints of the rendering within this part of its half-size, RANSAC model, inliers needed);
# the smallest reach follows a target off the ground (a rock), whose image moves unlike the ground's (parallax)
FEATURE_CANDIDATES = ((0.15, "similarity", 6), (0.3, "homography", 12), (0.5, "homography", 12),
                      (1.0, "homography", 12))
FEATURE_FINE_RADIUS_PX = 20.0  # NCC refinement radius around a feature-guided coarse position
FEATURE_LOCAL_PX = 75.0  # inliers within this many new pixels of the target are counted as local
# NCC must land within this of the feature match to confirm it; an unconfirmed match with fewer local inliers
# than FEATURE_MIN_LOCAL is reported as a failed step (measured on the simulated runs: all such were > 10 px off)
FEATURE_CONFIRM_PX = 8.0
FEATURE_MIN_LOCAL = 5
# confirmed candidates whose NCC positions lie within this of the best-scoring one are pooled (weighted by score)
FEATURE_AGREE_PX = 2.0
BAND_PX = {"pancam": 6.0, "navcam": 3.0, "hazcam": 3.0}
STEREO_WINDOW_PX = {"pancam": 21, "navcam": 21, "hazcam": 21}


@dataclass
class ChainStep:
    position: tuple
    camera: str
    product_id: str
    kind: str  # "designate" | "track" | "handoff"
    predicted_uv: Optional[list]
    tracked_uv: Optional[list]
    mark_uv: Optional[list]
    error_px: Optional[float]
    ncc_peak: Optional[float]
    range_m: Optional[float]
    xyz_site_m: Optional[list]
    truth_xyz_site_m: Optional[list]
    error_3d_m: Optional[float]  # stereo point vs the true target, both in the true rover frame
    ok: bool
    reason: str = ""
    extra: dict = field(default_factory=dict)

    def to_dict(self):
        d = dict(self.__dict__)
        d["position"] = list(self.position)
        return d


_f = finite_or_none


def _stereo(dl: Downlink, left: ImageProduct, uv):
    from ..core.point_stereo import point_stereo

    right = dl.stereo_pair(left)
    if right is None:
        return None
    return point_stereo(left.pixels_float(), right.pixels_float(), left.camera_model, right.camera_model,
                        np.asarray(uv, float), band_px=BAND_PX.get(left.camera, 4.0),
                        window_px=STEREO_WINDOW_PX.get(left.camera, 11))


def _local_normal_site(dl: Downlink, prod: ImageProduct, X_rover: np.ndarray, range_m: float):
    """Surface normals (site frame) at ``X_rover`` from half-resolution dense stereo of ``prod``'s pair.

    Returns ``(local, ground)``: the plane fitted within ``max(0.05, 0.025
    range)`` m (the target's own surface, e.g. a rock face) and within
    ``max(0.2, 0.1 range)`` m (mostly the surrounding ground); each ``(3,)`` or None.
    """
    from ..core.dense_stereo import dense_stereo
    from .designate import surface_normal

    right = dl.stereo_pair(prod)
    if right is None:
        return None, None
    try:
        ds = dense_stereo(prod.pixels_float(), right.pixels_float(), prod.camera_model, right.camera_model,
                          min_range_m=max(0.3, 0.6 * range_m), max_range_m=1.6 * range_m + 0.5, downsample=2)
    except Exception:
        return None, None
    xyz = ds.xyz.reshape(-1, 3)
    out = []
    for radius_m in (max(0.05, 0.025 * range_m), max(0.2, 0.1 * range_m)):
        n, npts = surface_normal(xyz, X_rover, radius_m=radius_m)
        out.append(None if n is None else prod.pose.T_site_rover.rotate(n))
    return tuple(out)


def render_through_plane(prev: ImageProduct, prod: ImageProduct, X_site, n_site, uv) -> np.ndarray:
    """``prev``'s image seen at ``prod``'s pixels ``uv`` (..., 2) through the plane (X_site, n_site), site frame.

    Each pixel's ray (``prod``'s camera at its pose estimate) meets the plane
    through ``X_site`` (3,) with normal ``n_site`` (3,); the point is projected
    into ``prev`` (its pose estimate) and ``prev``'s image is sampled there
    (bilinear). Returns float32 (...) with NaN where ``prev`` did not see it.
    """
    from ..core.expected import bilinear_sample

    uv = np.asarray(uv, float)
    shape = uv.shape[:-1]
    o, d = prod.camera_model.unproject(uv.reshape(-1, 2))
    T_new = prod.pose.T_site_rover
    o_s, d_s = T_new.apply(o), T_new.rotate(d)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((np.asarray(X_site) - o_s) @ n_site) / (d_s @ n_site)
    P_s = o_s + t[:, None] * d_s
    P_s[~(t > 0)] = np.nan
    P_prev = prev.pose.T_site_rover.inverse().apply(P_s)
    uv_prev = prev.camera_model.project(P_prev)
    return bilinear_sample(prev.pixels_float(), uv_prev).reshape(shape)


def plane_warped_view(prev: ImageProduct, prod: ImageProduct, X_site, n_site, centre_uv, half: int,
                      step_px: float = 1.0):
    """``prod``'s view of the window around ``centre_uv`` rendered from ``prev``'s image through a plane.

    See :func:`render_through_plane`. View pixel ``(i, j)`` is ``prod`` pixel
    ``c + step_px * ((i, j) - half)`` with ``c`` = ``centre_uv`` rounded
    (``step_px > 1``: a coarser rendering, e.g. at ``prev``'s own
    resolution). Returns ``(view (2h+1, 2h+1) float32 with NaN where ``prev``
    did not see the plane, centre_in_view_uv (2,))``: ``centre_uv`` in the
    view's pixel coordinates.
    """
    c = np.round(np.asarray(centre_uv, float))
    g = np.arange(-half, half + 1) * float(step_px)
    us, vs = np.meshgrid(c[0] + g, c[1] + g)
    vals = render_through_plane(prev, prod, X_site, n_site, np.stack([us, vs], -1))
    return vals, (np.asarray(centre_uv, float) - c) / float(step_px) + half


def plane_warped_template(prev: ImageProduct, prod: ImageProduct, X_site, n_site, centre_uv, half: int):
    """The window of ``prod`` around ``centre_uv`` as ``prev`` saw it, through the local plane (X_site, n_site).

    Each template pixel's ray (new camera, new pose estimate) meets the plane;
    the point is projected into the previous image and sampled. Returns
    ``(template (2h+1, 2h+1) float32 or None, template_center_uv (2,))``.
    """
    vals, tc = plane_warped_view(prev, prod, X_site, n_site, centre_uv, half)
    if np.isfinite(vals).mean() < 0.9:
        return None, None
    vals = np.where(np.isfinite(vals), vals, np.nanmean(vals)).astype(np.float32)
    return vals, tc


def run_chain(dl: Downlink, start: ImageProduct, start_uv, target_id: Optional[str] = None,
              handoff_method: str = "consensus", template_mode: str = "plane", handoff_at: str = "every") -> list:
    """Follow the target from ``start`` (a left pancam or navcam image) to the last hazcam image.

    ``template_mode``: ``"plane"`` (default) renders the previous stop's image
    into the new view through the local surface plane (from dense stereo) and
    finds the pose error with features first (:func:`_feature_track`), falling
    back to NCC over the search region (reported unverified) when no feature
    model is found; ``"scale"`` scales the previous window uniformly by the
    IFOV and range ratios and NCC-tracks it over the search region (the paper's
    way, no features). The pancam->navcam handoff at the same stop always
    scales the pancam window by the IFOV ratio, as the paper does; a handoff
    from a pancam image at an earlier stop (the 4.5 m pancam track was not
    trusted) goes through the feature path. Returns the list of
    :class:`ChainStep`; the last step is the navcam->hazcam handoff by
    ``handoff_method`` (near navcams) when a hazcam pair exists.
    ``handoff_at``: at which stops with hazcam images the navcam->hazcam
    handoff is made: ``"every"`` (default; the navcam track goes on through
    all stops, each handoff is a step, the last one has ``extra["final"]``
    True: the one the arm would use), ``"last"`` (only the last such stop),
    ``"first"`` (the chain ends at the first such stop). A step with
    ``ok=False`` whose ``reason`` starts ``weak match`` or ``unverified`` has a
    pixel that is reported but not used as the next stop's reference.
    """
    if template_mode not in ("plane", "scale"):
        raise ValueError(f"template_mode must be 'plane' or 'scale', got {template_mode!r}")
    if handoff_at not in ("every", "last", "first"):
        raise ValueError(f"handoff_at must be 'every', 'last' or 'first', got {handoff_at!r}")
    from ..core.tracking import track
    from ..core.windows import extract_window, scale_window, window_scale_for_handoff

    tgt = None
    truth_xyz = None
    if target_id is not None:
        try:
            tgt = dl.target(target_id)
        except InputError:
            tgt = None
        tt = dl.truth_target(target_id)
        truth_xyz = None if tt is None else np.asarray(tt.xyz_site_m, float)

    def mark(prod):
        if tgt is None:
            return None
        m = tgt.mark_in(prod.product_id)
        return None if m is None else [m.u, m.v]

    def step(prod, kind, pred, uv, ps, ncc=None, ok=True, reason="", extra=None):
        mk = mark(prod)
        err = None if (mk is None or uv is None) else float(np.hypot(uv[0] - mk[0], uv[1] - mk[1]))
        xyz_site = None
        e3 = None
        rng = None
        if ps is not None and ps.ok:
            xyz_site = prod.pose.T_site_rover.apply(np.asarray(ps.xyz, float))
            rng = _f(ps.range_m)
            tp = dl.truth_for(prod.product_id)
            if truth_xyz is not None and tp is not None:
                # in the rover frame, where stereo measures it (the site-frame error is mostly pose-estimate error)
                X_true_rover = tp.pose.T_site_rover.inverse().apply(truth_xyz)
                e3 = float(np.linalg.norm(np.asarray(ps.xyz, float) - X_true_rover))
        return ChainStep(prod.position, prod.camera, prod.product_id, kind,
                         None if pred is None else [float(x) for x in pred],
                         None if uv is None else [float(x) for x in uv], mk, err, _f(ncc), rng,
                         None if xyz_site is None else xyz_site.tolist(),
                         None if truth_xyz is None else truth_xyz.tolist(), e3, ok, reason, extra or {})

    steps = []
    uv = np.asarray(start_uv, float)
    ps = _stereo(dl, start, uv)
    if ps is None or not ps.ok:
        reason = "no right eye" if ps is None else ps.reason
        raise InputError(start.product_id, "pixel", f"designation has no stereo: {reason}")
    steps.append(step(start, "designate", None, uv, ps))
    X_site = start.pose.T_site_rover.apply(np.asarray(ps.xyz, float))
    prev, prev_uv, prev_range = start, uv, float(ps.range_m)
    cam = start.camera
    normal, ground, normal_from = None, None, None
    feats = {}  # product_id -> keypoints of the whole image (each new image is searched once)

    positions = [p for p in dl.positions() if p != start.position]
    positions = [p for p in positions if min(im.time_s for im in dl.images_at(p)) > start.time_s]
    haz_positions = [p for p in positions if dl.images_at(p, "hazcam", "left")] or [None]
    for pos in positions:
        lefts = {im.camera: im for im in sorted(dl.images_at(pos, eye="left"), key=lambda i: i.time_s)}
        order = []
        if cam in lefts:
            order.append(cam)
        if cam == "pancam" and "navcam" in lefts:
            order.append("navcam")
        for c in order:
            prod = lefts[c]
            X_rover = prod.pose.T_site_rover.inverse().apply(X_site)
            pred = prod.camera_model.project(X_rover[None])[0]
            rng_new = float(np.linalg.norm(X_rover - prod.camera_model.C))
            if not np.all(np.isfinite(pred)):
                steps.append(step(prod, "track", None, None, None, ok=False, reason="target behind the camera"))
                continue
            scale = window_scale_for_handoff(1.0 / prev.camera_model.hs, prev_range, 1.0 / prod.camera_model.hs, rng_new)
            half = TEMPLATE_HALF_PX.get(c, 15)
            kind = "handoff" if c != prev.camera else "track"
            tpl, tc, mode = None, None, "scale"
            radius_override, search_uv = None, None
            extra = {}
            tr = None
            # the pose error lies between stops: a track, or a handoff from a camera at an earlier stop
            if template_mode == "plane" and (kind == "track" or prev.position != prod.position):
                if normal_from is not prev:
                    X_prev = prev.pose.T_site_rover.inverse().apply(X_site)
                    (normal, ground), normal_from = _local_normal_site(dl, prev, X_prev, prev_range), prev
                # the surface plane at the target (or the rover's ground plane when dense stereo gave no normal)
                # renders the template; the coarse step also tries the surrounding ground's plane
                up = prev.pose.T_site_rover.rotate([0.0, 0.0, -1.0])
                n_view = normal if normal is not None else (ground if ground is not None else up)
                planes = [n_view]
                if ground is not None and np.degrees(np.arccos(np.clip(ground @ n_view, -1, 1))) > 5.0:
                    planes.append(ground)
                tr, finfo = _feature_track(prev, prod, X_site, planes, n_view, pred, scale, half, feats)
                extra.update(finfo)
                if tr is not None:
                    mode = "plane, feature-guided"
                elif normal is not None:
                    extra["coarse"] = "ncc context (features failed)"
                    # fallback: a large window of the previous view, warped through the local plane, found over
                    # the whole search region by NCC; then the target window near it
                    big_half = CONTEXT_HALF_PX.get(c, 100)
                    tpl_big, tc_big = plane_warped_template(prev, prod, X_site, normal, pred, big_half)
                    tr_big = None
                    if tpl_big is not None:
                        tr_big = track(tpl_big, prod.pixels_float(), pred, SEARCH_RADIUS_PX.get(c, 60.0),
                                       template_center_uv=tc_big, min_score=0.3)
                    # the template shows the previous view of the plane around the target, built around the
                    # pose-estimate prediction (where the warp puts the target at the template's centre)
                    tpl, tc = plane_warped_template(prev, prod, X_site, normal, pred, half)
                    mode = "plane"
                    if tr_big is not None and tr_big.ok and np.all(np.isfinite(tr_big.uv)):
                        search_uv = tr_big.uv  # searched for near the prediction corrected for the pose error
                        radius_override = FINE_RADIUS_PX
                        mode = "plane, context-corrected"
            if tr is None:
                if tpl is None:
                    src_half = max(3, int(np.ceil(half / scale)))
                    win = extract_window(prev.pixels_float(), prev_uv, src_half)
                    tpl = scale_window(win, scale)
                    tc = None
                img = prod.pixels_float()
                radius = radius_override or SEARCH_RADIUS_PX.get(c, 60.0)
                search_uv = search_uv if radius_override else pred
                tr = track(tpl, img, search_uv, radius, template_center_uv=tc, min_score=0.3)
                # a pointed mast camera was aimed at the target by the rover: its image centre is a second guess
                centre = np.array([(prod.width - 1) / 2, (prod.height - 1) / 2])
                if prod.mast is not None and radius_override is None and np.linalg.norm(centre - pred) > radius / 2:
                    tr2 = track(tpl, img, centre, radius, template_center_uv=tc, min_score=0.3)
                    if np.all(np.isfinite(tr2.uv)) and (not np.all(np.isfinite(tr.uv)) or tr2.score > tr.score):
                        tr = tr2
            if not tr.ok or not np.all(np.isfinite(tr.uv)):
                steps.append(step(prod, kind, pred, None, None, tr.score, ok=False, reason=f"track: {tr.reason}"))
                continue
            ps = _stereo(dl, prod, tr.uv)
            ok = ps is not None and ps.ok
            reasons = [] if ok else ["no right eye" if ps is None else f"stereo: {ps.reason}"]
            weak = False
            if extra.get("feature_status") == "unconfirmed":
                # a position from feature matches alone is an extrapolation of a RANSAC model: it moved by pixels
                # with the OpenCV build or one DN of noise (docs/stereo-and-tracking.md, "Reproducibility"), so it
                # is reported but never the next stop's reference (no count threshold to flip across)
                nl = extra.get("feature_local_inliers", 0)
                weak = True
                reasons.append(f"weak match: position from the feature match alone ({nl} keypoint matches near the "
                               f"target); NCC did not confirm it")
            elif extra.get("feature_status") == "failed":
                # measured on the simulated runs: NCC alone over the pose error's search region was wrong
                # every time the features failed, so its answer is reported but not trusted
                weak = True
                reasons.append(f"unverified: no feature match ({extra.get('feature_reason', '')}); "
                               f"NCC-only answer over a {radius:g} px search")
            steps.append(step(prod, kind, pred, tr.uv, ps, tr.score, ok=ok and not weak, reason="; ".join(reasons),
                              extra={"scale": scale, "template": mode, "ncc_ratio": _f(tr.ratio),
                                     "reference": prev.product_id, "unverified": weak, **extra}))
            if weak:  # not a reference for the next stop: the next one is tracked from the last good one
                continue
            if ok:
                X_site = prod.pose.T_site_rover.apply(np.asarray(ps.xyz, float))
                prev_range = float(ps.range_m)
            else:
                # no stereo: the tracked pixel's ray at the predicted range keeps the estimate consistent with the
                # pixel in this pose (a handoff at the same stop then predicts without the pose error)
                o, d = prod.camera_model.unproject(np.asarray(tr.uv, float)[None])
                X_site = prod.pose.T_site_rover.apply(o[0] + rng_new * d[0])
                prev_range = rng_new
            prev, prev_uv, cam = prod, tr.uv, c
        if "hazcam" in lefts and cam == "navcam" and prev.position == pos:
            if handoff_at != "last" or pos == haz_positions[-1]:
                steps.append(_hazcam_handoff(dl, prev, prev_uv, lefts["hazcam"], handoff_method, step))
            if handoff_at == "first":
                break
    handoffs = [s for s in steps if s.camera == "hazcam" and s.kind == "handoff"]
    for s in handoffs:
        s.extra["final"] = s is handoffs[-1]
    _mark_after_unverified(steps)
    return steps


def _mark_after_unverified(steps: list) -> None:
    """Steps after an unverified one carry ``extra["follows_unverified"]`` (its product id) and say so.

    The chain skips an unverified step as a reference (the next stop is
    tracked from the last verified image, across a longer drive and a
    larger change of scale), so whatever error that longer step makes is
    magnified by every later zoom. The step itself may be right (s1-straight
    t1: 2.1-3.3 px at the hazcam), but it is not the chain the operator
    expects, and ``reason`` says so.
    """
    first = None
    for s in steps:
        if first is not None and s.kind in ("track", "handoff"):
            s.extra["follows_unverified"] = first
            note = f"warning: follows the unverified step at {first}"
            s.reason = f"{s.reason}; {note}" if s.reason else note
        elif first is None and s.extra.get("unverified"):
            first = s.product_id


def _feature_track(prev: ImageProduct, prod: ImageProduct, X_site, view_normals, n_site, pred_uv, scale: float,
                   half: int, feats: dict):
    """Track the target from ``prev`` into ``prod`` guided by features; ``(TrackResult or None, info dict)``.

    For each plane normal in ``view_normals`` (site frame, planes through
    ``X_site``), ``prev``'s image is rendered into ``prod``'s view around the
    prediction ``pred_uv`` (:func:`plane_warped_view`) at ``prev``'s own
    resolution (one rendered pixel per ``scale`` new pixels, ``scale`` = new
    pixels per previous pixel at the target, at least 1), so that scale and
    perspective changes are taken out by the geometry and what is left is the
    pose-estimate error (a shift and a small rotation). Its SIFT keypoints
    near the target are matched against those of the whole new image
    (area-downsampled by the same factor, so that both have the same blur) and
    a homography ``G`` (pose-estimate pixels of ``prod`` -> real pixels) is
    fitted by RANSAC, with keypoints from a few reaches and models (``FEATURE_CANDIDATES``)
    around the target. For each ``G``, the template (half-size ``half``) is
    rendered through the target's plane ``n_site`` at the pixels ``G^-1``
    maps the new image's to, so that it carries the rotation of the pose
    error too, and NCC-tracked within ``FINE_RADIUS_PX`` of the mapped
    prediction; the best NCC wins. ``feats`` caches the new images' keypoints
    by ``(product id, downsampling)``. ``info`` records the path, the
    winner's inlier counts and the coarse position.
    """
    from ..core.features import detect_features, locate_by_features
    from ..core.tracking import TrackResult, track

    info = {"coarse": "features", "feature_inliers": 0, "feature_local_inliers": 0}
    img = prod.pixels_float()
    g = np.arange(-half, half + 1, dtype=float)
    c = np.round(np.asarray(pred_uv, float))
    cands, seen, reasons = [], [], []

    def confirmed(cd):
        loc, tr = cd[0], cd[1]
        return tr.ok and np.all(np.isfinite(tr.uv)) and np.linalg.norm(tr.uv - loc.uv) <= FEATURE_CONFIRM_PX

    for factor in FEATURE_STEP_FACTORS:
        if any(confirmed(cd) for cd in cands):
            break  # a coarser rendering only when nothing was confirmed at the finer one
        step_px = float(np.clip(scale * factor, 1.0, 4.0 * factor))
        vhalf = int(round(VIEW_REACH_PX / step_px))
        key = (prod.product_id, round(step_px, 2))
        if key not in feats:
            feats[key] = detect_features(prod.pixels_float(), downsample=step_px)
        # pose-estimate pixels of prod -> rendering pixels
        S = np.array([[1 / step_px, 0, vhalf - c[0] / step_px], [0, 1 / step_px, vhalf - c[1] / step_px],
                      [0, 0, 1.0]])
        for k, n_view in enumerate(view_normals):
            view, vc = plane_warped_view(prev, prod, X_site, n_view, pred_uv, vhalf, step_px=step_px)
            if np.isfinite(view).mean() < 0.2:
                reasons.append(f"plane {k}: the previous view does not cover the prediction")
                continue
            ref = detect_features(view)
            for reach, model, min_inliers in FEATURE_CANDIDATES:
                loc = locate_by_features(ref, vc, feats[key], ref_radius_px=reach * vhalf, model=model,
                                         ransac_threshold_px=2.0 * step_px, min_inliers=min_inliers,
                                         local_radius_px=FEATURE_LOCAL_PX / step_px)
                if not loc.ok:
                    reasons.append(f"x{factor:g} plane {k} reach {reach:g}: {loc.reason}")
                    continue
                if any(np.linalg.norm(loc.uv - q) < 1.0 for q in seen):
                    continue
                seen.append(loc.uv)
                try:
                    Gi = np.linalg.inv(loc.transform @ S)
                except np.linalg.LinAlgError:
                    continue
                cc = np.round(loc.uv)
                xs = np.stack(np.meshgrid(cc[0] + g, cc[1] + g), -1).reshape(-1, 2)
                yh = np.c_[xs, np.ones(len(xs))] @ Gi.T
                with np.errstate(divide="ignore", invalid="ignore"):
                    ys = yh[:, :2] / yh[:, 2:3]
                tpl = render_through_plane(prev, prod, X_site, n_site, ys).reshape(2 * half + 1, 2 * half + 1)
                if np.isfinite(tpl).mean() < 0.9:
                    continue
                tpl = np.where(np.isfinite(tpl), tpl, np.nanmean(tpl)).astype(np.float32)
                tr = track(tpl, img, loc.uv, FEATURE_FINE_RADIUS_PX, template_center_uv=loc.uv - (cc - half),
                           min_score=0.3)
                cands.append((loc, tr, k, reach, factor))
    if not cands:
        info["feature_status"] = "failed"
        info["feature_reason"] = "; ".join(reasons) or "no usable feature model"
        return None, info
    # Several candidates (planes, reaches, resolutions) measure the same position. A candidate is confirmed when
    # NCC refines it to a peak near its feature match. The answer pools the candidates instead of taking the
    # single best, so that which candidate scores a hair higher does not move the answer by their spread:
    # confirmed -> the score-weighted mean of the confirmed NCC positions within FEATURE_AGREE_PX of the best one;
    # none confirmed -> the inlier-weighted geometric median of the feature matches (reported as such).
    good = [cd for cd in cands if confirmed(cd)]
    if good:
        best = max(good, key=lambda cd: (cd[1].score, -cd[2], cd[3], cd[4]))
        near = [cd for cd in good if np.linalg.norm(cd[1].uv - best[1].uv) <= FEATURE_AGREE_PX]
        w = np.array([max(cd[1].score, 1e-3) for cd in near])
        uv = (w[:, None] * np.array([cd[1].uv for cd in near])).sum(0) / w.sum()
        loc, tr, k, reach, factor = best
        info["feature_status"] = "confirmed"
        info["feature_pooled"] = len(near)
        out = TrackResult(True, "", uv, best[1].score, best[1].second_score, best[1].ratio, best[1].sharpness,
                          best[1].levels)
    else:
        pts = np.array([cd[0].uv for cd in cands])
        w = np.array([max(cd[0].n_inliers, 1) for cd in cands], float)
        uv = geometric_median(pts, w)
        loc, tr, k, reach, factor = min(cands, key=lambda cd: (np.linalg.norm(cd[0].uv - uv), -cd[0].n_inliers))
        info["feature_status"] = "unconfirmed"
        info["feature_pooled"] = len(cands)
        # the NCC peak found elsewhere is not this position's score: recorded in info only
        out = TrackResult(True, "", uv, float("nan"), float("nan"), float("nan"), float("nan"), 0)
    info.update({"feature_inliers": loc.n_inliers, "feature_local_inliers": loc.n_local_inliers,
                 "feature_matches": loc.n_matches, "feature_reach": reach, "feature_plane": k,
                 "feature_candidates": len(cands), "feature_confirmed": len(good), "feature_step_factor": factor,
                 "feature_shift_px": float(np.linalg.norm(out.uv - pred_uv)), "coarse_uv": loc.uv.tolist(),
                 "ncc_uv": tr.uv.tolist() if np.all(np.isfinite(tr.uv)) else None, "ncc_score": _f(tr.score)})
    return out, info


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


def _hazcam_handoff(dl, nav, nav_uv, haz, method, step):
    from ..core.handoff import run_method
    from .handoff import build_setup

    setup = build_setup(dl, hazcam=haz.product_id, near=nav.product_id)
    case = setup.cases["near"]
    res = run_method(case, method, nav_uv)
    uv = res.uv if res.uv is not None and np.all(np.isfinite(res.uv)) else None
    ps = _stereo(dl, haz, uv) if uv is not None else None
    return step(haz, "handoff", None, uv, ps, res.diagnostics.get("ncc_peak"), ok=uv is not None,
                reason=res.reason, extra={"method": method, "navcam": "near", "reference": nav.product_id})
