"""Point stereo: range one left pixel by NCC along its epipolar band (pure numerics).

Frames: every 3-D quantity is in the frame of the camera models passed in
(for downlink products, the rover frame at acquisition). Pixels follow
docs/conventions.md: ``(u, v)`` = (column, row), ``(0, 0)`` the centre of the
top-left pixel. Range is the distance from the left camera's ``C``.

As in the SCIP handoff paper (:func:`point_stereo`): a window around the left
pixel is correlated (zero-mean NCC, :mod:`scipctl.core.ncc`) with the right
image within a band of ``band_px`` around the epipolar curve
(:func:`scipctl.core.epipolar.epipolar_curve`). The best match is refined to
sub-pixel precision and the two rays are intersected (closest approach,
:func:`scipctl.core.triangulation.triangulate_rays`). The signed perpendicular
distance of the match from the epipolar curve is a calibration-health figure
(the paper saw up to ~4 px on pancams).

OpenCV is imported inside the functions (``scipctl --help`` stays fast).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .camera import CameraModel, check_camera_model
from .epipolar import epipolar_curve, pixel_ray, polyline_foot
from .image import as_float_image
from .ncc import default_min_std, local_maxima, ncc_region, refine_subpixel_peak, subpixel_peak
from .triangulation import triangulate_rays
from .windows import crop_window

__all__ = ["DEFAULT_BAND_PX", "PointStereoParams", "PointStereoResult", "point_stereo"]

#: Epipolar band half-widths (px) per camera: wide enough for the ~4 px
#: misalignment the paper saw on pancams, ~1 px (x 3 margin) on navcams.
DEFAULT_BAND_PX = {"pancam": 6.0, "navcam": 3.0, "hazcam": 3.0}


@dataclass(frozen=True)
class PointStereoParams:
    """Per-camera band half-width and window of point stereo at a chosen pixel (:func:`point_stereo`'s
    ``band_px`` and ``window_px``): a designation (``scipctl designate``) and each step of the tracking chain.

    A camera not in a dict takes the ``other_*`` value (e.g. ``mastcamz`` from PDS products). These are
    the values the designation and the chain have always used; the calibration-health figures of the report
    use their own instance (``scipctl.pipeline.report_data.ReportParams.calibration_stereo``).
    """

    band_px: dict = field(default_factory=lambda: dict(DEFAULT_BAND_PX))
    window_px: dict = field(default_factory=lambda: {"pancam": 21, "navcam": 21, "hazcam": 21})
    other_band_px: float = 4.0
    other_window_px: int = 11

    @classmethod
    def with_band(cls, band_px: float) -> "PointStereoParams":
        """The defaults with one band half-width for every camera (an operator's ``--band-px``)."""
        return cls(band_px={}, other_band_px=float(band_px))

    def check(self) -> "PointStereoParams":
        """Raise ValueError naming the first bad field; return self."""
        for name, values, fallback, integer in (("band_px", self.band_px, self.other_band_px, False),
                                                ("window_px", self.window_px, self.other_window_px, True)):
            if not isinstance(values, dict):
                raise ValueError(f"PointStereoParams.{name}: expected a {{camera: value}} dict, got {values!r}")
            for cam, v in list(values.items()) + [("other cameras", fallback)]:
                if integer:
                    ok = isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= 3
                else:
                    ok = isinstance(v, (int, float, np.number)) and not isinstance(v, bool) and np.isfinite(v) and v >= 0
                if not ok:
                    what = "an integer >= 3" if integer else "a finite number >= 0"
                    raise ValueError(f"PointStereoParams.{name}[{cam!r}]: must be {what}, got {v!r}")
        return self

    def band(self, camera: str) -> float:
        """Band half-width (px) for ``camera``."""
        return self.band_px.get(camera, self.other_band_px)

    def window(self, camera: str) -> int:
        """Correlation window side (px) for ``camera``."""
        return self.window_px.get(camera, self.other_window_px)


@dataclass(frozen=True)
class PointStereoResult:
    """Outcome of :func:`point_stereo` (NaN fields where not computed).

    ``xyz`` (3,): the target in the models' frame (midpoint of the two rays'
    closest approach). ``range_m``: ``|xyz - C_left|``. ``range_sigma_m``:
    range uncertainty for a matching uncertainty of ``disparity_sigma_px``
    along the epipolar curve. ``uv_right`` (2,): the sub-pixel match.
    ``score``: peak NCC; ``second_score``/``ratio``: best competing match
    in the band and ``score / second_score``; ``sharpness``: peak curvature
    (per px^2). ``epipolar_offset_px``: signed perpendicular distance of the
    match from the epipolar curve (sign convention in :func:`point_stereo`),
    a calibration-health figure. ``miss_distance_m``: distance between the
    two rays at closest approach.
    """

    ok: bool
    reason: str
    xyz: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    range_m: float = float("nan")
    range_sigma_m: float = float("nan")
    uv_right: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))
    score: float = float("nan")
    second_score: float = float("nan")
    ratio: float = float("nan")
    sharpness: float = float("nan")
    epipolar_offset_px: float = float("nan")
    miss_distance_m: float = float("nan")


def _band_mask(curve_pl: np.ndarray, shape: tuple, band_px: float) -> np.ndarray:
    """Boolean ``shape`` mask of grid points within ``band_px`` of polyline ``curve_pl`` (grid pixel units)."""
    import cv2

    shift = 4
    canvas = np.zeros(shape, np.uint8)
    pts = np.round(curve_pl * (1 << shift)).astype(np.int32).reshape(-1, 1, 2)
    cv2.polylines(canvas, [pts], False, 255, thickness=1, lineType=cv2.LINE_8, shift=shift)
    if not canvas.any():
        return np.zeros(shape, bool)
    dist = cv2.distanceTransform(255 - canvas, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return dist <= band_px


def on_left_ray(model, uv, xyz) -> np.ndarray:
    """The point of the left-image ray of pixel ``uv`` (2,) nearest to the stereo point ``xyz`` (3,), both in the
    model's frame; returns (3,).

    :func:`point_stereo` returns the midpoint of the left and right rays' closest approach. When the right eye's
    calibration is off (the unsynchronised right exposure of a rocking mast), the rays miss each other and the
    midpoint lies off the left ray: it projects back into the left image a few tenths of a pixel from the measured
    pixel (0.1-0.3 px, always the same sign, on the simulated navcams; docs/stereo-and-tracking.md, "The drift's
    cause"). The left pixel is the measurement of the target's direction; stereo gives its range. The chain
    (every stop's estimate) and the handoff methods (the navcam target point, ``HandoffCase.point_stereo``) use it.
    """
    o, d = model.unproject(np.asarray(uv, float).reshape(1, 2))
    X = np.asarray(xyz, float).reshape(3)
    return o[0] + float((X - o[0]) @ d[0]) * d[0]


def point_stereo(
    left_img,
    right_img,
    left_model: CameraModel,
    right_model: CameraModel,
    uv_left,
    band_px: float = 6.0,
    window_px: int = 21,
    min_range_m: float = 0.3,
    max_range_m: float = 100.0,
    min_score: float = 0.6,
    disparity_sigma_px: float = 0.25,
    min_window_std: Optional[float] = None,
    saturation_level: Optional[float] = None,
    max_saturated_fraction: float = 0.25,
    subpixel_iterations: int = 4,
    affine: bool = True,
) -> PointStereoResult:
    """Range one left pixel by NCC matching in a band around its epipolar curve.

    Parameters
    ----------
    left_img, right_img : (H, W) arrays (uint8, uint16 or float)
    left_model, right_model : CameraModel
        Same frame (e.g. rover frame at acquisition); any kind.
    uv_left : (2,)
        The left pixel (sub-pixel allowed).
    band_px : float
        Half-width of the search band around the epipolar curve (right
        pixels); see :class:`PointStereoParams` (per camera).
    window_px : int
        Side of the correlation window (odd; an even value is increased by 1).
        Near the image border the window is clipped to the image (at least
        half of it must be inside).
    min_range_m, max_range_m : float
        Range interval of the epipolar curve searched.
    min_score : float
        Peak NCC below this -> ``ok=False``.
    disparity_sigma_px : float
        Matching uncertainty along the epipolar curve, propagated to
        ``range_sigma_m`` by finite differences of the triangulation.
    min_window_std : float, optional
        Texture threshold for the left window (image units; default
        :func:`scipctl.core.ncc.default_min_std`).
    saturation_level : float, optional
        Pixel value counted as saturated (default: the dtype's maximum for
        integer images, none for float images).
    max_saturated_fraction : float
        More saturated pixels than this fraction in the left window -> ``ok=False``.
    affine : bool
        Refine the match with a window warp that lets the disparity vary
        linearly across the window (surfaces seen obliquely, e.g. the ground:
        a translation-only NCC peak is then biased by 0.1-0.7 px on our test
        scenes; with the warp, ~0.05 px). Costs a few milliseconds.

    Returns
    -------
    PointStereoResult
        ``ok=False`` with ``reason`` one of: "pixel outside image", "window
        mostly outside image", "saturated window", "textureless window",
        "epipolar curve outside the right image", "no match above threshold
        ...", "match at the edge of the epipolar band ...", "rays do not
        converge", "intersection behind a camera".

    The signed ``epipolar_offset_px`` is ``(uv_right - foot) . n`` with
    ``foot`` the nearest curve point and ``n`` the curve's unit normal
    ``(-t_v, t_u)``, ``t`` the unit tangent oriented towards increasing ``u``
    (towards increasing ``v`` for a vertical curve): for a left-to-right curve
    a positive offset means the match lies below (larger ``v``).
    """
    check_camera_model(left_model, "left_model")
    check_camera_model(right_model, "right_model")
    ldtype = np.asarray(left_img).dtype
    L = as_float_image(left_img, "left_img")
    R = as_float_image(right_img, "right_img")
    uv = np.asarray(uv_left, dtype=float).reshape(-1)
    if uv.shape != (2,) or not np.all(np.isfinite(uv)):
        raise ValueError(f"uv_left: expected a finite (u, v) pair, got {uv_left!r}")
    if not (band_px >= 0 and np.isfinite(band_px)):
        raise ValueError(f"band_px: must be finite and >= 0, got {band_px}")
    window_px = int(window_px)
    if window_px < 3:
        raise ValueError(f"window_px: must be >= 3, got {window_px}")
    half = window_px // 2
    if not (0 < min_range_m < max_range_m and np.isfinite(max_range_m)):
        raise ValueError(f"ranges: need 0 < min_range_m < max_range_m < inf, got {min_range_m}, {max_range_m}")
    H, W = L.shape
    if not (-0.5 <= uv[0] <= W - 0.5 and -0.5 <= uv[1] <= H - 0.5):
        return PointStereoResult(False, "pixel outside image")

    # --- the left window
    tpl_raw, c_win, frac = crop_window(np.asarray(left_img), uv, half)
    if frac < 0.5:
        return PointStereoResult(False, "window mostly outside image")
    if saturation_level is None and ldtype.kind in "ui":
        saturation_level = float(np.iinfo(ldtype).max)
    if saturation_level is not None:
        sat = float(np.mean(np.asarray(tpl_raw, dtype=float) >= saturation_level))
        if sat > max_saturated_fraction:
            return PointStereoResult(False, f"saturated window ({100 * sat:.0f}% of pixels at {saturation_level:g})")
    tpl = as_float_image(tpl_raw, "left window")
    if min_window_std is None:
        min_window_std = default_min_std(ldtype)
    if float(tpl.std()) < min_window_std:
        return PointStereoResult(False, f"textureless window (std {float(tpl.std()):.3g} < {min_window_std:g})")
    th, tw = tpl.shape
    tpl0 = tpl - np.float32(tpl.mean())

    # --- the epipolar curve and the band
    curve, curve_r = epipolar_curve(left_model, right_model, uv, min_range_m, max_range_m)
    Hr, Wr = R.shape
    if len(curve) >= 2:
        inside = (
            (curve[:, 0] >= -0.5 - band_px) & (curve[:, 0] <= Wr - 0.5 + band_px)
            & (curve[:, 1] >= -0.5 - band_px) & (curve[:, 1] <= Hr - 0.5 + band_px)
        )
        keep = np.nonzero(inside)[0]
    else:
        keep = np.zeros(0, int)
    if len(keep) < 2:
        return PointStereoResult(False, "epipolar curve outside the right image")
    curve_in = curve[keep[0] : keep[-1] + 1]
    # top-left placements of the window whose centre point lies within the band's bounding box
    lo = np.floor(curve_in.min(0) - band_px - 1 - c_win).astype(int)
    hi = np.ceil(curve_in.max(0) + band_px + 1 - c_win).astype(int)
    res = ncc_region(tpl0, R, lo[0], hi[0], lo[1], hi[1])
    if res is None:
        return PointStereoResult(False, "epipolar curve outside the right image")
    m, x0, y0 = res
    # grid (x, y) of the map <-> right pixel (x0 + x + c_win_u, y0 + y + c_win_v)
    mask = _band_mask(curve_in - c_win - np.array([x0, y0]), m.shape, band_px)
    if not mask.any():
        return PointStereoResult(False, "epipolar curve outside the right image")

    ys, xs = local_maxima(m, mask)
    if len(ys) == 0:
        return PointStereoResult(False, "no correlation peak in the epipolar band")
    by, bx = int(ys[0]), int(xs[0])
    score = float(m[by, bx])
    excl = max(2.0, min(th, tw) / 4.0)
    second = -1.0
    for yy, xx in zip(ys[1:], xs[1:]):
        if (yy - by) ** 2 + (xx - bx) ** 2 > excl * excl:
            second = float(m[yy, xx])
            break
    # a band-limited maximum that is not a maximum of the unrestricted map: the true peak is outside the band
    y_lo, y_hi = max(by - 1, 0), min(by + 2, m.shape[0])
    x_lo, x_hi = max(bx - 1, 0), min(bx + 2, m.shape[1])
    at_band_edge = float(m[y_lo:y_hi, x_lo:x_hi].max()) > score

    dx, dy, sharp = subpixel_peak(m, by, bx)
    peak_xy = np.array([x0 + bx, y0 + by], dtype=float)
    if subpixel_iterations > 0:
        it = refine_subpixel_peak(tpl0, R, peak_xy, (dx, dy), subpixel_iterations)
        if it is not None:
            (dx, dy), sharp, sc = it
            score = max(score, sc)
    uv_r = peak_xy + np.array([dx, dy]) + c_win
    if affine:
        aff = _affine_refine(tpl0, R, uv_r, c_win, _along_curve(curve, uv_r))
        if aff is not None:
            uv_r, score, _ = aff
    ratio = score / second if second > 0 else float("inf")

    foot, tan, _, _ = polyline_foot(curve, uv_r)
    if tan[0] < 0 or (tan[0] == 0 and tan[1] < 0):
        tan = -tan
    normal = np.array([-tan[1], tan[0]])
    offset = float(np.dot(uv_r - foot, normal))

    common = dict(uv_right=uv_r, score=score, second_score=second, ratio=ratio, sharpness=sharp,
                  epipolar_offset_px=offset)
    if score < min_score:
        return PointStereoResult(False, f"no match above threshold (peak NCC {score:.3f} < {min_score:.3f})", **common)
    if at_band_edge:
        return PointStereoResult(
            False, f"match at the edge of the epipolar band (models misaligned by more than {band_px:g} px?)", **common
        )

    o1, d1 = pixel_ray(left_model, uv)
    along = _along_curve(curve, uv_r)

    def tri(p):
        o2, d2 = pixel_ray(right_model, p)
        return triangulate_rays(o1, d1, o2, d2)

    X, miss, t = tri(uv_r)
    common["miss_distance_m"] = float(miss)
    if not np.all(np.isfinite(X)):
        return PointStereoResult(False, "rays do not converge", **common)
    if t[0] <= 0 or t[1] <= 0:
        return PointStereoResult(False, "intersection behind a camera", **common)
    rng = float(np.linalg.norm(X - left_model.C))
    h = 0.5
    Xp, _, tp = tri(uv_r + h * along)
    Xm, _, tm = tri(uv_r - h * along)
    rp = float(np.linalg.norm(Xp - left_model.C))
    rm = float(np.linalg.norm(Xm - left_model.C))
    if np.isfinite(rp) and np.isfinite(rm) and tp[0] > 0 and tm[0] > 0:
        sigma = abs(rp - rm) / (2 * h) * disparity_sigma_px
    else:
        sigma = float("inf")
    return PointStereoResult(True, "", xyz=X, range_m=rng, range_sigma_m=float(sigma), **common)


def _affine_refine(tpl0: np.ndarray, R: np.ndarray, uv_r: np.ndarray, c_win: np.ndarray, tangent: np.ndarray,
                   max_gradient: float = 0.6):
    """Refine a match allowing the disparity to vary linearly across the window.

    A surface that is not fronto-parallel (the ground seen obliquely) has a
    disparity gradient ``g`` (px per px): the right-image view of the window
    is sheared/stretched along the epipolar direction ``tangent``, and a
    translation-only NCC peak is biased by tenths of a pixel. We maximise the
    NCC over the warp ``x -> uv_r + x - tangent (g . x)`` (``x``: template
    offsets from the tracked point ``c_win``; bicubic resampling) in the
    4 parameters (translation, ``g``) with Nelder-Mead, starting from the
    translation-only match. Returns ``(uv_r (2,), score, g (2,))`` or ``None``
    when it did not improve the NCC or wandered more than 1.5 px.
    """
    from scipy.optimize import minimize

    from .resample import sample_bicubic_uv

    th, tw = tpl0.shape
    ys, xs = np.mgrid[0:th, 0:tw].astype(np.float64)
    x = xs - c_win[0]
    y = ys - c_win[1]
    t = np.asarray(tangent, dtype=float)
    tn = tpl0.astype(np.float64).ravel()
    tn = tn - tn.mean()
    tnorm = np.sqrt(np.dot(tn, tn))
    n = tn.size
    # per evaluation (hundreds per call): U = base_u + du - t_u (gx x + gy y), likewise V (computed together,
    # (2, th, tw): the same operations on each element); the template is zero-mean, so
    # sum((p - mean p) tn) = sum(p tn) and sum((p - mean p)^2) = sum(p^2) - (sum p)^2 / n
    base = np.stack([uv_r[0] + x, uv_r[1] + y])
    t_x = np.stack([t[0] * x, t[1] * x])
    t_y = np.stack([t[0] * y, t[1] * y])

    def ncc(p):
        gx, gy = p[2], p[3]
        UV = base + p[:2, None, None] - (gx * t_x + gy * t_y)
        patch = sample_bicubic_uv(R, UV).ravel()
        sp = patch.sum()
        var = float(np.dot(patch, patch)) - sp * sp / n
        den = np.sqrt(var) * tnorm if var > 0 else 0.0
        return float(np.dot(patch, tn) / den) if den > 0 else -1.0

    def cost(p):
        if abs(p[2]) > max_gradient or abs(p[3]) > max_gradient:
            return 2.0
        return -ncc(p)

    p0 = np.zeros(4)
    s0 = ncc(p0)
    simplex = np.array([p0, [0.3, 0, 0, 0], [0, 0.3, 0, 0], [0, 0, 0.05, 0], [0, 0, 0, 0.05]])
    res = minimize(cost, p0, method="Nelder-Mead",
                   options=dict(initial_simplex=simplex, xatol=1e-4, fatol=1e-9, maxiter=600, maxfev=1200))
    p = res.x
    if -res.fun <= s0 or np.hypot(p[0], p[1]) > 1.5:
        return None
    return uv_r + p[:2], float(-res.fun), p[2:].copy()


def _along_curve(curve: np.ndarray, p: np.ndarray) -> np.ndarray:
    _, tan, _, _ = polyline_foot(curve, p)
    return tan
