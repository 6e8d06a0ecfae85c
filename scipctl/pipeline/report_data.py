"""Everything the diagnostic report shows, computed from a downlink (no file access; docs/report.md).

:func:`collect` gathers, per target: the designation, the tracking chain
through the downlink's stops, the navcam->hazcam handoff results of every
method (reused from ``handoff.json`` when given), the pre-uplink prediction
and the uplink sequence with its rule checks; for the downlink: calibration
health (epipolar offsets by point stereo and from marks, a systematic mast
bias estimate) and gain/saturation diagnostics. Image chips are returned as
arrays (annotated later by the HTML writer); no plotting here.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Optional

import numpy as np

from ..core.image import full_scale
from ..core.point_stereo import PointStereoParams
from ..model import Downlink, InputError
from .designate import Designation

SAT_WARN = 0.01  # saturated fraction above which an image is flagged
DARK_WARN = 0.2  # fraction of pixels within 2 % of black
PAIR_RATIO_WARN = 1.25  # left/right mean brightness ratio (autogain difference)


@dataclass
class ReportParams:
    chip_half_px: int = 40
    run_handoff: bool = True  # when there is no handoff.json
    # methods run when there is no handoff.json: the paper's, except the slow whole-cloud mesh registration
    # (~20 s on a 1024 px downlink); `scipctl simulate-handoff` runs them all and saves handoff.json for the report
    fresh_methods: tuple = ("pure-kinematic", "alt-pure-kinematic", "refined-kinematic", "pure-geometric",
                            "refined-geometric")
    run_chain: bool = True
    run_prediction: bool = True
    n_track_samples: int = 4
    n_mc_samples: int = 500
    calib_points_per_pair: int = 5
    sigma_position_m: Optional[float] = None  # pose-error sigmas for the prediction (None: from the downlink)
    sigma_yaw_rad: Optional[float] = None
    # point stereo on textured points for the calibration-health offsets: a 15 px pancam window, 11 px for the
    # other cameras, and a 6 px band for cameras other than pancam/navcam/hazcam (the band is looked up by the
    # lower-cased camera name, the window by the name as given)
    calibration_stereo: PointStereoParams = field(default_factory=lambda: PointStereoParams(
        window_px={"pancam": 15}, other_window_px=11, other_band_px=6.0))
    # the rule set's prediction parameters (``--rules``; None: the defaults); the report's sample counts above
    # and sigmas replace its uncertainty fields
    predict: Optional[object] = None

    def check(self) -> "ReportParams":
        """Raise ValueError naming the first bad field; return self."""
        for name, lo in (("chip_half_px", 1), ("n_track_samples", 0), ("n_mc_samples", 1), ("calib_points_per_pair", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise ValueError(f"ReportParams.{name}: must be an integer >= {lo}, got {v!r}")
        for name in ("sigma_position_m", "sigma_yaw_rad"):
            v = getattr(self, name)
            if v is not None and not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                                      and v >= 0):
                raise ValueError(f"ReportParams.{name}: must be a number >= 0 or None, got {v!r}")
        self.calibration_stereo.check()
        return self


@dataclass
class ChipMarker:
    kind: str  # designated | predicted | tracked | true | expected
    label: str
    uv: tuple
    method: Optional[str] = None  # a handoff prediction's method (kind "predicted"): its colour on the page
    navcam: Optional[str] = None  # and the navcam it started from ("near" | "far"): its marker's shape


@dataclass
class Chip:
    target: str
    product_id: str
    camera: str
    position: tuple
    title: str
    image: np.ndarray  # (h, w) float [0, 1]
    origin_uv: tuple  # full-image pixel of image[0, 0]
    markers: list = field(default_factory=list)
    scale: float = 1.0  # full-image pixels per chip pixel (expected views are reduced)


# ============================================================================ images: gain and saturation
def image_stats(dl: Downlink) -> list:
    """Per image product: exposure, gain, normalised mean and percentiles, saturated and dark fractions, flags."""
    out = []
    means = {}
    for im in sorted(dl.images, key=lambda i: i.time_s):
        px = im.pixels
        top, bits = full_scale(px)  # 12-bit data in 16-bit words judged against 4095, not 65535
        f = px.astype(np.float64) / top
        sat = float(np.mean(px >= top))
        dark = float(np.mean(f <= 0.02))
        p1, p50, p99 = (float(x) for x in np.percentile(f, [1, 50, 99]))
        rec = {"product_id": im.product_id, "camera": im.camera, "eye": im.eye, "position": list(im.position),
               "exposure_ms": im.exposure_ms, "gain": im.gain, "bits": bits,
               "mean": float(f.mean()), "p1": p1, "p50": p50, "p99": p99, "saturated_fraction": sat,
               "dark_fraction": dark, "flags": []}
        if sat > SAT_WARN:
            rec["flags"].append(f"saturated {100 * sat:.1f}%")
        if dark > DARK_WARN:
            rec["flags"].append(f"dark {100 * dark:.0f}%")
        if p99 - p1 < 0.1:
            rec["flags"].append("low contrast")
        means[im.product_id] = rec["mean"]
        out.append(rec)
    by_id = {r["product_id"]: r for r in out}
    for im in dl.images:
        if im.eye != "left":
            continue
        right = dl.stereo_pair(im)
        if right is None or right.product_id not in means or means[right.product_id] <= 0:
            continue
        ratio = means[im.product_id] / means[right.product_id]
        by_id[im.product_id]["pair_ratio"] = ratio
        if not (1 / PAIR_RATIO_WARN <= ratio <= PAIR_RATIO_WARN):
            by_id[im.product_id]["flags"].append(f"left/right brightness ratio {ratio:.2f}")
    return out


# ============================================================================ calibration health
def _epipolar_offset(left_model, right_model, uv_left, uv_right) -> Optional[float]:
    """Signed distance (px) of ``uv_right`` from the epipolar curve of ``uv_left``, with point stereo's sign
    (``PointStereoResult.epipolar_offset_px``: the tangent oriented towards increasing u, + below the curve)."""
    from ..core.epipolar import epipolar_curve, polyline_foot

    try:
        c, _ = epipolar_curve(left_model, right_model, uv_left, 0.3, 200.0)
    except ValueError:
        return None
    if len(c) < 2:
        return None
    p = np.asarray(uv_right, float)
    foot, _, k, _ = polyline_foot(c, p)
    seg = c[k + 1] - c[k]  # the tangent of the foot's own segment
    tan = seg / max(math.sqrt(float(seg @ seg)), 1e-12)
    if tan[0] < 0 or (tan[0] == 0 and tan[1] < 0):  # the curve runs far -> near (decreasing u): orient as point_stereo
        tan = -tan
    d = p - foot
    return float(tan[0] * d[1] - tan[1] * d[0])


def _texture_points(img: np.ndarray, n: int, margin: int = 40) -> np.ndarray:
    """Up to ``n`` well-textured pixels (Shi-Tomasi corners), spread over the image."""
    import cv2

    a = np.asarray(img, np.float32)
    u8 = np.clip(a / max(float(np.percentile(a, 99.5)), 1e-6) * 255, 0, 255).astype(np.uint8)
    H, W = u8.shape
    mask = np.zeros_like(u8)
    mask[margin:H - margin, margin:W - margin] = 255
    pts = cv2.goodFeaturesToTrack(u8, maxCorners=n, qualityLevel=0.01, minDistance=max(8, min(H, W) // 6), mask=mask)
    return np.zeros((0, 2)) if pts is None else pts.reshape(-1, 2).astype(float)


def calibration_health(dl: Downlink, points_per_pair: int = 5, stereo: Optional[PointStereoParams] = None) -> dict:
    """Epipolar offsets per stereo pair (point stereo on textured points, with ``stereo``'s band and window,
    default :attr:`ReportParams.calibration_stereo`; and from marks) and a mast bias estimate."""
    from ..core.point_stereo import point_stereo

    stereo = (stereo or ReportParams().calibration_stereo).check()

    pairs = []
    for im in sorted(dl.images, key=lambda i: i.time_s):
        if im.eye != "left":
            continue
        right = dl.stereo_pair(im)
        if right is None:
            continue
        L, R = im.pixels_float(), right.pixels_float()
        offs = []
        for uv in _texture_points(L, points_per_pair):
            try:
                ps = point_stereo(L, R, im.camera_model, right.camera_model, uv,
                                  band_px=stereo.band(str(im.camera).lower()), window_px=stereo.window(im.camera))
            except ValueError:
                continue
            if ps.ok and np.isfinite(ps.epipolar_offset_px):
                offs.append(float(ps.epipolar_offset_px))
        marks = []
        for t in dl.targets:
            ml, mr = t.mark_in(im.product_id), t.mark_in(right.product_id)
            if ml is not None and mr is not None:
                o = _epipolar_offset(im.camera_model, right.camera_model, [ml.u, ml.v], [mr.u, mr.v])
                if o is not None:
                    marks.append({"target": t.id, "offset_px": o})
        pairs.append({"left": im.product_id, "right": right.product_id, "camera": im.camera, "position": list(im.position),
                      "point_stereo_offsets_px": offs,
                      "median_offset_px": float(np.median(offs)) if offs else None,
                      "mark_offsets": marks})
    return {"pairs": pairs, "mast_bias": mast_bias(dl)}


def _head_delta(rc, pan, tilt, dpan, dtilt):
    """Rover-frame motion taking the head from (pan, tilt) to (pan + dpan, tilt + dtilt)."""
    return rc.mast.head_motion(pan + dpan, tilt + dtilt) @ rc.mast.head_motion(pan, tilt).inverse()


def mast_bias(dl: Downlink) -> Optional[dict]:
    """Systematic mast (pan, tilt) bias from marks: the angles that best make the navcam-triangulated targets
    project onto their hazcam marks at the same rover position (the paper's 13-row kinematic-handoff bias).

    Exact for pan and tilt encoder offsets; mast errors the two angles cannot represent (a tilt axis turned about
    the pan axis, a displaced head) are taken up into them as far as they move the marks (docs/report.md, "What the
    pan estimate holds").

    Returns ``{cases, dpan_rad, dtilt_rad, residual_before_px (mean du, dv), rms_before_px, rms_after_px}``
    or None without suitable marks (near navcam pair + hazcam left at one position, all marked).
    """
    from ..core.triangulation import triangulate_rays

    rc = dl.rover_config
    cases = []
    for haz in dl.images:
        if haz.camera != "hazcam" or haz.eye != "left":
            continue
        for nl in dl.images_at(haz.position, camera="navcam", eye="left"):
            nr = dl.stereo_pair(nl)
            if nr is None or nl.mast is None:
                continue
            for t in dl.targets:
                a, b, h = t.mark_in(nl.product_id), t.mark_in(nr.product_id), t.mark_in(haz.product_id)
                if a is not None and b is not None and h is not None:
                    cases.append((nl, nr, haz, np.array([a.u, a.v]), np.array([b.u, b.v]), np.array([h.u, h.v])))
    if not cases:
        return None

    def resid(q):
        out = []
        for nl, nr, haz, a, b, h in cases:
            D = _head_delta(rc, nl.mast.pan_rad, nl.mast.tilt_rad, q[0], q[1])
            ml, mr = nl.camera_model.transformed(D), nr.camera_model.transformed(D)
            o1, d1 = ml.unproject(a[None])
            o2, d2 = mr.unproject(b[None])
            X, _, _ = triangulate_rays(o1[0], d1[0], o2[0], d2[0])
            out.append(haz.camera_model.project(X[None])[0] - h)
        return np.array(out)

    r0 = resid(np.zeros(2))
    if not np.all(np.isfinite(r0)):
        return None
    q = np.zeros(2)
    for _ in range(10):
        r = resid(q).ravel()
        J = np.stack([(resid(q + e).ravel() - r) / 1e-6 for e in (np.array([1e-6, 0]), np.array([0, 1e-6]))], axis=1)
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        q = q + step
        if np.linalg.norm(step) < 1e-9:
            break
    r1 = resid(q)
    out = {"cases": len(cases), "dpan_rad": float(q[0]), "dtilt_rad": float(q[1]),
           "residual_before_px": r0.mean(axis=0).tolist(), "rms_before_px": float(np.sqrt(np.mean(np.sum(r0 ** 2, 1)))),
           "rms_after_px": float(np.sqrt(np.mean(np.sum(r1 ** 2, 1)))) if np.all(np.isfinite(r1)) else None}
    out["truth"] = _mast_truth(dl, cases)
    return out


def _mast_truth(dl: Downlink, cases) -> Optional[dict]:
    """With simulation truth: the actual navcam-to-hazcam rotation error, as (pan, tilt)-like angles about rover z, y."""
    nl, _, haz, *_ = cases[0]
    tn, th = dl.truth_for(nl.product_id), dl.truth_for(haz.product_id)
    if tn is None or th is None:
        return None
    from ..core.camera import T_model_cam

    def R_hazcam_navcam(mn, mh):
        R_rover_navcam, R_rover_hazcam = T_model_cam(mn).R, T_model_cam(mh).R
        return R_rover_hazcam.T @ R_rover_navcam

    # true vs believed navcam-to-hazcam rotation, hazcam frame
    E = R_hazcam_navcam(tn.camera_model, th.camera_model) @ R_hazcam_navcam(nl.camera_model, haz.camera_model).T
    R_rover_hazcam = T_model_cam(haz.camera_model).R
    Er = R_rover_hazcam @ E @ R_rover_hazcam.T  # in the rover frame
    w = np.array([Er[2, 1] - Er[1, 2], Er[0, 2] - Er[2, 0], Er[1, 0] - Er[0, 1]]) / 2.0
    return {"rotation_rad": float(np.linalg.norm(w)), "about_rover_z_rad": float(w[2]), "about_rover_y_rad": float(w[1])}


# ============================================================================ chips
def _crop(img: np.ndarray, centre, half: int):
    H, W = img.shape
    c = np.round(np.asarray(centre, float)).astype(int)
    u0, v0 = int(c[0] - half), int(c[1] - half)
    out = np.full((2 * half + 1, 2 * half + 1), np.nan, np.float32)
    us0, vs0 = max(u0, 0), max(v0, 0)
    us1, vs1 = min(u0 + 2 * half + 1, W), min(v0 + 2 * half + 1, H)
    if us1 > us0 and vs1 > vs0:
        out[vs0 - v0:vs1 - v0, us0 - u0:us1 - u0] = img[vs0:vs1, us0:us1]
    return out, (u0, v0)


def _norm(img):
    a = np.asarray(img, np.float32)
    ok = np.isfinite(a)
    if not ok.any():
        return np.zeros_like(a)
    lo, hi = np.percentile(a[ok], [1, 99])
    hi = max(hi, lo + 1e-6)
    return np.where(ok, np.clip((a - lo) / (hi - lo), 0, 1), np.nan).astype(np.float32)


def chips_for_target(dl: Downlink, target_id: str, record: Optional[Designation], chain_steps: list,
                     handoff_records: list, half: int, hazcam_product: Optional[str]) -> list:
    """One chip per left image where the target is marked, tracked or predicted, with every position on it.

    ``chain_steps``: :class:`~scipctl.pipeline.chain.ChainStep`; ``handoff_records``:
    :class:`~scipctl.pipeline.handoff.HandoffRecord`, predicting into the
    left hazcam image ``hazcam_product``.
    """
    tm = next((t for t in dl.targets if t.id == target_id), None)
    steps = {s.product_id: s for s in chain_steps}
    preds = {}
    for r in handoff_records:
        if r.target == target_id and r.predicted_uv is not None:
            preds.setdefault(hazcam_product, []).append(r)
    chips = []
    for im in sorted((i for i in dl.images if i.eye == "left"), key=lambda i: (i.time_s, i.camera)):
        marks = []
        mk = tm.mark_in(im.product_id) if tm is not None else None
        if mk is not None:
            marks.append(ChipMarker("true", "true (mark)", (mk.u, mk.v)))
        if record is not None and record.product_id == im.product_id:
            marks.append(ChipMarker("designated", "designated", tuple(record.pixel_uv)))
        st = steps.get(im.product_id)
        if st is not None:
            if st.predicted_uv is not None:
                marks.append(ChipMarker("expected", "chain prediction", tuple(st.predicted_uv)))
            if st.tracked_uv is not None:
                marks.append(ChipMarker("tracked", f"tracked ({st.kind})", tuple(st.tracked_uv)))
        for r in sorted(preds.get(im.product_id, []), key=lambda r: (r.method, r.navcam)):
            marks.append(ChipMarker("predicted", f"{r.method} ({r.navcam})", tuple(r.predicted_uv), r.method, r.navcam))
        if not marks:
            continue
        ref = next((m.uv for m in marks if m.kind == "true"), None) or next(
            (m.uv for m in marks if m.kind in ("designated", "tracked")), marks[0].uv)
        img, origin = _crop(im.pixels_float(), ref, half)
        chips.append(Chip(target_id, im.product_id, im.camera, im.position,
                          f"{im.product_id} ({im.camera}, position {im.position[0]}/{im.position[1]})",
                          _norm(img), origin, marks))
    return chips


def expected_view_chips(pred) -> list:
    """The prediction's rendered views (reduced size) with the expected target pixel (``Chip.scale``: full-image
    pixels per view pixel; a full-image pixel ``uv`` is at ``(uv + 0.5) / scale - 0.5`` in the view)."""
    chips = []
    for st in pred.plan.stops[1:]:
        for sh in st.cameras:
            v = pred.views.get((st.index, sh.camera))
            if v is None:
                continue
            w = v.image.shape[1]
            scale = float(getattr(v, "full_width", w)) / w
            marks = [ChipMarker("expected", "expected target", (sh.uv[0], sh.uv[1]))] if sh.uv is not None else []
            chips.append(Chip(pred.target_id, f"stop {st.index} {sh.camera}", sh.camera, (st.index,),
                              f"stop {st.index} ({st.kind}, {st.distance_m:.2f} m): {sh.camera}", _norm(v.image),
                              (0, 0), marks, scale))
    return chips


# ============================================================================ prediction vs later images
def prediction_check(dl: Downlink, record: Designation, pred, half: int = 40, search_px: int = 150) -> tuple:
    """Check the prediction against the images of this downlink taken after today's position.

    For each later left image where the target is marked: the expected pixel
    of the designated 3-D target through the image's model and downlinked
    (estimated) pose, against the mark (pose-estimate error included); with
    simulation truth also through the true model and pose (the designation's
    error alone); and today's terrain rendered around the mark through the
    true model and pose when known (else the downlinked ones), NCC-matched to
    the real image (best shift within ``search_px``): the fidelity of the
    expected views. Returns ``(rows, chips)``.
    """
    import cv2

    terrain = pred.terrain
    tm = next((t for t in dl.targets if t.id == record.id), None)
    if terrain is None or tm is None:
        return [], []
    today = dl.product(record.product_id)
    X = np.asarray(record.xyz_site_m, float)
    rows, chips = [], []
    for im in sorted((i for i in dl.images if i.eye == "left" and i.position != today.position and i.time_s > today.time_s),
                     key=lambda i: i.time_s):
        mk = tm.mark_in(im.product_id)
        if mk is None:
            continue
        ms = im.camera_model.transformed(im.pose.T_site_rover)
        uv_exp = ms.project(X[None])[0]
        tr = dl.truth_for(im.product_id)
        uv_true_pose = None
        if tr is not None:
            ms = tr.camera_model.transformed(tr.pose.T_site_rover)  # render at the true pose
            uv_true_pose = ms.project(X[None])[0]
        c = np.round([mk.u, mk.v]).astype(int)
        R = half + search_px
        view = terrain.render(ms, 0, 0, roi=(int(c[0] - R), int(c[1] - R), 2 * R + 1, 2 * R + 1))
        actual, origin = _crop(im.pixels_float(), c, half)
        row = {"product_id": im.product_id, "camera": im.camera, "position": list(im.position),
               "mark_uv": [mk.u, mk.v], "expected_uv": uv_exp.tolist() if np.all(np.isfinite(uv_exp)) else None,
               "expected_error_px": float(np.hypot(*(uv_exp - [mk.u, mk.v]))) if np.all(np.isfinite(uv_exp)) else None,
               "expected_error_true_pose_px": (float(np.hypot(*(uv_true_pose - [mk.u, mk.v])))
                                               if uv_true_pose is not None and np.all(np.isfinite(uv_true_pose)) else None),
               "render_pose": "true" if tr is not None else "downlinked",
               "coverage": view.coverage, "ncc": None, "shift_px": None}
        inner = view.image[search_px:search_px + 2 * half + 1, search_px:search_px + 2 * half + 1]
        if view.coverage > 0.1 and np.isfinite(actual).all():
            big = np.where(np.isfinite(view.image), view.image, np.nanmean(view.image)).astype(np.float32)
            m = cv2.matchTemplate(big, actual.astype(np.float32), cv2.TM_CCOEFF_NORMED)
            _, best, _, loc = cv2.minMaxLoc(m)
            row["ncc"] = float(best)
            row["shift_px"] = [float(loc[0] - search_px), float(loc[1] - search_px)]  # rendered content offset
            inner = view.image[loc[1]:loc[1] + 2 * half + 1, loc[0]:loc[0] + 2 * half + 1]  # aligned for display
        rows.append(row)
        marks = [ChipMarker("true", "true (mark)", (mk.u, mk.v))]
        if row["expected_uv"] is not None:
            marks.append(ChipMarker("expected", "expected (designated 3-D, downlinked pose)", tuple(row["expected_uv"])))
        chips.append(Chip(record.id, im.product_id, im.camera, im.position, f"{im.product_id}: actual",
                          _norm(actual), origin, marks))
        sh = row["shift_px"] or [0.0, 0.0]
        chips.append(Chip(record.id, im.product_id, im.camera, im.position,
                          f"{im.product_id}: expected from today's stereo (aligned, shift {sh[0]:+.0f}, {sh[1]:+.0f} px)",
                          _norm(inner), (origin[0] + sh[0], origin[1] + sh[1]), []))
    return rows, chips


# ============================================================================ the whole report
def _all_target_ids(dl: Downlink, designations: list) -> list:
    ids = [t.id for t in dl.targets]
    for r in designations:
        if r.id not in ids:
            ids.append(r.id)
    return ids


def collect(source_dl: Downlink, designations: Optional[list], saved_handoff: Optional[tuple],
            params: Optional[ReportParams] = None, progress=None, saved_chains: Optional[dict] = None) -> dict:
    """All report content for a downlink (see the module docstring). ``progress(str)`` is called as work proceeds.

    ``designations``: the :class:`Designation` records of ``targets.json``
    (:func:`~scipctl.pipeline.designate.designations_from_doc`); ``saved_handoff``: ``(records, table1 rows)``
    from ``handoff.json`` (:func:`~scipctl.pipeline.handoff.handoff_records_from_doc`) or None (the methods are
    run here). Per target the data holds its ``record`` (:class:`Designation` or None), ``chain``
    (:class:`~scipctl.pipeline.chain.ChainStep` list) and ``handoff``
    (:class:`~scipctl.pipeline.handoff.HandoffRecord` list). ``saved_chains``: ``{key: ChainStep list}`` of
    ``handoff.json`` (:func:`~scipctl.pipeline.chain_key.keyed_chains_from_doc`); a target whose chain has its key
    there takes that chain instead of running it (``data["chain_sources"]`` says which did).
    """
    from .predict import PredictParams, Terrain, predict_target, resolve_target, terrain_sources

    p = (params or ReportParams()).check()
    dl = source_dl
    say = progress or (lambda s: None)
    secs = {}
    notes = []
    data = {"mission": dl.mission, "sol": dl.sol, "source": dl.source, "sha256": dl.source_sha256,
            "images": len(dl.images), "positions": [list(x) for x in dl.positions()], "has_truth": dl.has_truth,
            "targets": [], "notes": notes, "seconds": secs}

    # ---- designations
    t0 = time.perf_counter()
    records = {}
    designations = list(designations or [])
    for tid in _all_target_ids(dl, designations):
        try:
            rec, now = resolve_target(dl, tid, designations, with_normal=False)
            records[tid] = rec
        except InputError as e:
            notes.append(f"target {tid}: not designated ({e})")
    secs["designate"] = time.perf_counter() - t0

    # ---- handoff results (reuse handoff.json when present)
    t0 = time.perf_counter()
    handoff_records, table1_rows, handoff_source, hazcam_product = [], [], None, None
    if saved_handoff is not None and saved_handoff[0]:
        handoff_records = list(saved_handoff[0])
        table1_rows = list(saved_handoff[1] or [])
        handoff_source = "handoff.json (saved by simulate-handoff)"
        hazcam_product = _guess_hazcam(dl)
    elif p.run_handoff and dl.targets:
        say("handoff methods")
        try:
            from .handoff import build_setup, marked_targets, run_targets, table1

            setup = build_setup(dl)
            recs = run_targets(dl, setup, marked_targets(dl, setup), methods=p.fresh_methods,
                               downlink_name=dl.source or "")
            handoff_records = list(recs)
            hazcam_product = setup.hazcam.product_id
            table1_rows = table1(recs)
            handoff_source = ("computed for this report (" + ", ".join(p.fresh_methods) + "; run `scipctl "
                              "simulate-handoff` first to include every method, the report then reuses handoff.json)")
        except (InputError, ValueError) as e:
            notes.append(f"handoff methods not run: {e}")
    secs["handoff"] = time.perf_counter() - t0
    data["handoff"] = {"source": handoff_source, "records": handoff_records, "table1": table1_rows,
                       "hazcam_product": hazcam_product}

    # ---- tracking chains through the downlink's stops
    t0 = time.perf_counter()
    chains, chain_sources = {}, {}
    data["chain_sources"] = chain_sources
    if p.run_chain:
        from .chain import ChainParams, run_chain
        from .chain_key import chain_key

        # shared by the targets' chains, as simulate-handoff --chain shares them (run_chain: what is computed once
        # per downlink, the hazcam handoffs' setups and each image's keypoints, gives the same answers)
        setups, features = {}, {}
        for tid, rec in records.items():
            start = next((i for i in dl.images if i.product_id == rec.product_id), None)
            if start is None:
                continue
            key = chain_key(dl, start.product_id, rec.pixel_uv, tid, ChainParams()) if saved_chains else None
            if key is not None and key in saved_chains:
                chains[tid] = saved_chains[key]
                chain_sources[tid] = "from handoff.json (saved by simulate-handoff --chain)"
                continue
            say(f"chain {tid}")
            chain_sources[tid] = "run by this report"
            try:
                chains[tid] = run_chain(dl, start, list(rec.pixel_uv), target_id=tid, setups=setups,
                                        feature_cache=features)
            except (InputError, ValueError) as e:
                notes.append(f"target {tid}: tracking chain not run ({e})")
    secs["chain"] = time.perf_counter() - t0

    # ---- calibration and images
    t0 = time.perf_counter()
    say("calibration health")
    data["calibration"] = calibration_health(dl, p.calib_points_per_pair, p.calibration_stereo)
    data["image_stats"] = image_stats(dl)
    secs["calibration"] = time.perf_counter() - t0

    # ---- predictions (one terrain per today's position)
    t0 = time.perf_counter()
    predictions = {}
    if p.run_prediction:
        base = p.predict or PredictParams()
        pp = replace(base, uncertainty=replace(base.uncertainty, n_track_samples=p.n_track_samples,
                                               n_samples=p.n_mc_samples, sigma_position_m=p.sigma_position_m,
                                               sigma_yaw_rad=p.sigma_yaw_rad))
        terrains = {}
        for tid, rec in records.items():
            if not rec.has_position:
                continue
            say(f"prediction {tid}")
            try:
                pos = dl.product(rec.product_id).position
                if pos not in terrains:
                    terrains[pos] = Terrain(terrain_sources(dl, pos, downsample=pp.stereo_downsample,
                                                            target_range_m=rec.range_m),
                                            pp.max_edge_ratio, pp.min_edge_m, pp.smooth_sigma_px)
                pr = predict_target(dl, rec, pp, terrain=terrains[pos])
                for (si, cam), v in pr.views.items():
                    v.full_width = dl.rover_config.spec(cam, "left").width
                predictions[tid] = pr
            except (InputError, ValueError) as e:
                notes.append(f"target {tid}: no prediction ({e})")
    secs["prediction"] = time.perf_counter() - t0

    # ---- per target
    for tid in _all_target_ids(dl, designations):
        rec = records.get(tid)
        steps = chains.get(tid, [])
        hrecs = [r for r in handoff_records if r.target == tid]
        tt = dl.truth_target(tid)
        err3d = None
        if rec is not None and tt is not None and rec.xyz_site_m is not None:
            err3d = float(np.linalg.norm(np.asarray(rec.xyz_site_m) - np.asarray(tt.xyz_site_m)))
        pr = predictions.get(tid)
        check_rows, check_chips = ([], []) if pr is None else prediction_check(dl, rec, pr, p.chip_half_px)
        data["targets"].append({
            "id": tid, "record": rec, "designation_error_m": err3d,
            "expected_chips": [] if pr is None else expected_view_chips(pr),
            "prediction_check": check_rows, "prediction_check_chips": check_chips,
            "chain": steps, "handoff": hrecs,
            "chips": chips_for_target(dl, tid, rec, steps, hrecs, p.chip_half_px, hazcam_product),
            "prediction": predictions.get(tid),
        })
    return data


def _guess_hazcam(dl: Downlink) -> Optional[str]:
    """handoff.json records lack the hazcam product id: the latest left hazcam (what simulate-handoff uses)."""
    hz = sorted((im for im in dl.images if im.camera == "hazcam" and im.eye == "left"), key=lambda i: i.time_s)
    return hz[-1].product_id if hz else None
