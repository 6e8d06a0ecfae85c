"""Normalised cross-correlation (NCC) tracking of image windows (pure numerics).

Pixel convention (docs/conventions.md): ``(u, v)`` = (column, row), 0-based,
``(0, 0)`` is the centre of the top-left pixel; an image is indexed
``img[v, u]``. Every ``uv`` here is a ``(2,)`` float array in that convention.

The tracker (:func:`track`) correlates a template with a bounded search
region of an image using zero-mean normalised cross-correlation (OpenCV
``matchTemplate`` with ``TM_CCOEFF_NORMED`` on float32), coarse-to-fine over
a Gaussian pyramid (``cv2.pyrDown``). The coarsest level searches the whole
region and keeps several candidate peaks; each is refined level by level in
a small neighbourhood; the finest level gives the peak NCC, a sub-pixel
position (quadratic fit to the 3x3 neighbourhood of the peak) and
diagnostics: the best competing peak (``second_score``), the ratio
``score / second_score`` and the peak sharpness (smallest curvature of the
NCC surface at the peak, per px^2; ~0 along an edge).

NCC is invariant to an affine intensity change ``a * I + b`` (``a > 0``) of
either image, so camera gain/offset differences do not matter.

Camera changes (pancam -> navcam handoff, far navcam -> hazcam): a target
seen at range ``r`` through IFOV ``i`` (rad/px) spans ``1 / (r * i)`` pixels
per metre, so a window taken in one camera is shrunk or enlarged by
:func:`window_scale_for_handoff` with :func:`scale_window` before tracking.

OpenCV is imported inside the functions (``scipctl --help`` stays fast).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .resample import sample_bicubic, sample_bilinear

__all__ = [
    "TrackResult",
    "track",
    "ncc_map",
    "subpixel_peak",
    "extract_window",
    "crop_window",
    "scale_window",
    "window_scale_for_handoff",
    "as_float_image",
    "default_min_std",
]

#: candidate peaks carried from the coarsest pyramid level to the finest
_N_CANDIDATES = 5
#: a search radius (coarsest level, px) above which another pyramid level is added
_COARSE_RADIUS_PX = 24
#: the template's smaller side is kept at least this large at the coarsest level
_MIN_COARSE_TEMPLATE_PX = 8
_MAX_LEVELS = 5


@dataclass(frozen=True)
class TrackResult:
    """Outcome of :func:`track`.

    ``uv`` (2,): where the template's centre point (``template_center_uv``)
    lies in the searched image (NaN when nothing was found). ``score``: peak
    NCC in [-1, 1] at the finest level, evaluated at the sub-pixel position
    (image resampled bicubically) when the sub-pixel iteration ran. ``second_score``: the best other
    local NCC maximum farther than ``exclusion_px`` from the peak (-1 when
    there is none). ``ratio``: ``score / second_score`` (``inf`` when
    ``second_score <= 0``); near 1 means an ambiguous (repeated) pattern.
    ``sharpness``: smallest curvature ``-d2(NCC)/dx2`` of the peak over all
    directions, per px^2 (``~0`` along an edge: the aperture problem).
    ``ok`` is ``False`` with a one-line ``reason`` when the track failed.
    ``levels``: number of pyramid levels above full resolution that were used.
    """

    ok: bool
    reason: str
    uv: np.ndarray
    score: float
    second_score: float
    ratio: float
    sharpness: float
    levels: int = 0

    @staticmethod
    def failed(reason: str, score: float = float("nan"), levels: int = 0) -> "TrackResult":
        return TrackResult(False, reason, np.full(2, np.nan), score, float("nan"), float("nan"), float("nan"), levels)


# ---------------------------------------------------------------- utilities
def as_float_image(img, name: str = "image") -> np.ndarray:
    """A single-channel image (``(H, W)``, any real dtype) as contiguous float32; checks the shape."""
    a = np.asarray(img)
    if a.ndim != 2:
        raise ValueError(f"{name}: expected a single-channel (H, W) image, got shape {a.shape}")
    if a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"{name}: empty image {a.shape}")
    if a.dtype.kind not in "uif" and a.dtype != bool:
        raise ValueError(f"{name}: unsupported dtype {a.dtype}")
    return np.ascontiguousarray(a, dtype=np.float32)


def default_min_std(dtype) -> float:
    """Default texture threshold (std of a window, in the image's own units).

    Integer images: half a digital number (a window varying by less than half
    a quantum is flat). Float images: ``1e-6`` (only an exactly flat window).
    """
    return 0.5 if np.dtype(dtype).kind in "ui" else 1e-6


def _as_uv(uv, name: str) -> np.ndarray:
    a = np.asarray(uv, dtype=float).reshape(-1)
    if a.shape != (2,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: expected a finite (u, v) pair, got {uv!r}")
    return a


def ncc_map(template, image) -> np.ndarray:
    """Zero-mean NCC of ``template`` ``(h, w)`` at every placement inside ``image`` ``(H, W)``.

    Returns ``(H - h + 1, W - w + 1)`` float32; entry ``[y, x]`` scores the
    template with its top-left pixel on image pixel ``(u=x, v=y)``. Both
    inputs are mean-subtracted first (the NCC is unchanged; the float32
    sums are better conditioned).
    """
    import cv2

    t = as_float_image(template, "template")
    im = as_float_image(image, "image")
    if t.shape[0] > im.shape[0] or t.shape[1] > im.shape[1]:
        raise ValueError(f"template {t.shape} larger than image {im.shape}")
    t = t - np.float32(t.mean())
    im = im - np.float32(im.mean())
    return cv2.matchTemplate(im, t, cv2.TM_CCOEFF_NORMED)


# 3x3 least-squares quadratic f = a + b x + c y + d x^2 + e x y + g y^2
_QX, _QY = np.meshgrid([-1.0, 0.0, 1.0], [-1.0, 0.0, 1.0])
_QDESIGN = np.stack(
    [np.ones(9), _QX.ravel(), _QY.ravel(), _QX.ravel() ** 2, (_QX * _QY).ravel(), _QY.ravel() ** 2], axis=1
)
_QPINV = np.linalg.pinv(_QDESIGN)


def subpixel_peak(score_map: np.ndarray, iy: int, ix: int) -> tuple[float, float, float]:
    """Sub-pixel offset ``(dx, dy)`` of the maximum at ``[iy, ix]`` of ``score_map`` ``(H, W)`` and its sharpness.

    Fits a quadratic to the 3x3 neighbourhood (least squares); if the fit
    is not a proper maximum or its vertex lies more than 1 px away, falls
    back to two 1-D parabolas through the centre row and column (each clipped
    to +-0.5 px). Sharpness is the smallest eigenvalue of ``-Hessian`` of the
    fitted surface (per px^2); 0 when the peak is on the map's border.
    """
    Hm, Wm = score_map.shape
    if not (0 <= iy < Hm and 0 <= ix < Wm):
        raise ValueError(f"peak index ({iy}, {ix}) outside map {score_map.shape}")
    if iy == 0 or ix == 0 or iy == Hm - 1 or ix == Wm - 1:
        return 0.0, 0.0, 0.0
    n = np.asarray(score_map[iy - 1 : iy + 2, ix - 1 : ix + 2], dtype=float)
    if not np.all(np.isfinite(n)):
        return 0.0, 0.0, 0.0
    _, b, c, d, e, g = _QPINV @ n.ravel()
    Hs = np.array([[2 * d, e], [e, 2 * g]])
    ev = np.linalg.eigvalsh(-Hs)
    sharp = float(max(ev.min(), 0.0))
    if ev.min() > 0:
        off = -np.linalg.solve(Hs, np.array([b, c]))
        if np.all(np.abs(off) <= 1.0):
            return float(off[0]), float(off[1]), sharp

    def para(fm, f0, fp):
        den = fm - 2 * f0 + fp
        if den >= 0:
            return 0.0
        return float(np.clip(0.5 * (fm - fp) / den, -0.5, 0.5))

    return para(n[1, 0], n[1, 1], n[1, 2]), para(n[0, 1], n[1, 1], n[2, 1]), sharp


def _iterate_subpixel(tpl: np.ndarray, img: np.ndarray, peak_xy, d0, iterations: int = 4):
    """Refine the sub-pixel offset ``d0`` of the NCC peak at integer top-left ``peak_xy``.

    A quadratic fitted to NCC samples 1 px apart is biased towards the
    sampling grid ("pixel locking") and by the peak's asymmetry (a cubic
    term; the bias shrinks with the square of the sample spacing). So we
    resample the image (bicubic) around the current estimate, evaluate the
    NCC on a 3x3 grid of spacing ``h`` (1, then 0.5, then 0.25 px) centred on
    it, and add the fitted vertex. Returns ``(d (2,), sharpness per px^2)``
    and the NCC at the refined position, or ``None`` when the template does
    not fit in the image at ``peak_xy`` or the refinement wanders off by more
    than a pixel. Near the image border the missing neighbourhood repeats the
    edge pixels.
    """
    import cv2

    th, tw = tpl.shape
    H, W = img.shape
    px, py = int(peak_xy[0]), int(peak_xy[1])
    pad = 4
    x0, y0 = px - pad, py - pad
    x1, y1 = px + tw + pad, py + th + pad
    if px < 0 or py < 0 or px + tw > W or py + th > H:
        return None
    crop = img[max(y0, 0) : y1, max(x0, 0) : x1]
    if x0 < 0 or y0 < 0 or x1 > W or y1 > H:  # at the image border: repeat the edge pixels
        crop = cv2.copyMakeBorder(
            crop, max(-y0, 0), max(y1 - H, 0), max(-x0, 0), max(x1 - W, 0), cv2.BORDER_REPLICATE
        )
    crop = crop - np.float32(crop.mean())
    # exact sampling positions (scipctl.core.resample): OpenCV 4.x would round them to 1/32 px
    gy, gx = np.mgrid[0:th, 0:tw].astype(np.float64)

    def shifted(du, dv):
        return sample_bicubic(crop, gx + pad + du, gy + pad + dv).astype(np.float32)

    d = np.array(d0, dtype=float)
    sharp = 0.0
    for it in range(iterations):
        h = 1.0 / 2 ** min(it, 2)
        m3 = np.empty((3, 3))
        for j in range(3):
            for i in range(3):
                patch = shifted(d[0] + (i - 1) * h, d[1] + (j - 1) * h)
                m3[j, i] = cv2.matchTemplate(patch, tpl, cv2.TM_CCOEFF_NORMED)[0, 0]
        dx, dy, sharp = subpixel_peak(m3, 1, 1)
        sharp /= h * h
        d += (dx * h, dy * h)
        if np.any(np.abs(d) > 1.0):
            return None
        if h <= 0.25 and abs(dx * h) < 1e-3 and abs(dy * h) < 1e-3:
            break
    patch = shifted(d[0], d[1])
    score = float(cv2.matchTemplate(patch, tpl, cv2.TM_CCOEFF_NORMED)[0, 0])
    return d, sharp, score


def _local_maxima(m: np.ndarray, valid: Optional[np.ndarray] = None) -> tuple[np.ndarray, np.ndarray]:
    """Row/column indices of 3x3 local maxima of ``m`` (ties kept), strongest first."""
    import cv2

    mm = np.where(np.isfinite(m), m, -np.inf).astype(np.float32)
    if valid is not None:
        mm = np.where(valid, mm, -np.inf).astype(np.float32)
    dil = cv2.dilate(mm, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_REPLICATE)
    peak = (mm >= dil) & np.isfinite(mm)
    ys, xs = np.nonzero(peak)
    order = np.argsort(-mm[ys, xs], kind="stable")
    return ys[order], xs[order]


def _select_peaks(m: np.ndarray, k: int, sep: float, valid: Optional[np.ndarray] = None) -> list[tuple[int, int, float]]:
    """Up to ``k`` local maxima of ``m``, strongest first, pairwise farther apart than ``sep`` px."""
    ys, xs = _local_maxima(m, valid)
    out: list[tuple[int, int, float]] = []
    for y, x in zip(ys, xs):
        if all((y - y2) ** 2 + (x - x2) ** 2 > sep * sep for y2, x2, _ in out):
            out.append((int(y), int(x), float(m[y, x])))
            if len(out) >= k:
                break
    return out


def _ncc_region(tpl: np.ndarray, img: np.ndarray, x0: int, x1: int, y0: int, y1: int):
    """NCC for top-left placements ``x0..x1``, ``y0..y1`` (inclusive), clipped to the image.

    Returns ``(map, x0c, y0c)`` or ``None`` when no placement fits.
    """
    import cv2

    th, tw = tpl.shape
    H, W = img.shape
    x0c, y0c = max(x0, 0), max(y0, 0)
    x1c, y1c = min(x1, W - tw), min(y1, H - th)
    if x1c < x0c or y1c < y0c:
        return None
    crop = img[y0c : y1c + th, x0c : x1c + tw]
    crop = crop - np.float32(crop.mean())
    return cv2.matchTemplate(crop, tpl, cv2.TM_CCOEFF_NORMED), x0c, y0c


def _pyramid(img: np.ndarray, levels: int) -> list[np.ndarray]:
    import cv2

    out = [img]
    for _ in range(levels):
        out.append(cv2.pyrDown(out[-1]))
    return out


def _auto_levels(search_radius_px: float, th: int, tw: int) -> int:
    levels = 0
    while (
        levels < _MAX_LEVELS
        and search_radius_px / 2**levels > _COARSE_RADIUS_PX
        and min(th, tw) / 2 ** (levels + 1) >= _MIN_COARSE_TEMPLATE_PX
    ):
        levels += 1
    return levels


def _refine(tpl, img, p_xy, rad: int, max_moves: int = 4):
    """Hill-climb a local NCC search of radius ``rad`` around integer top-left ``p_xy``.

    Returns ``(map, x0, y0, iy, ix)`` of the local map containing the peak in
    its interior (or on the image-clipped border), or ``None``.
    """
    px, py = int(p_xy[0]), int(p_xy[1])
    res = None
    for _ in range(max_moves):
        res = _ncc_region(tpl, img, px - rad, px + rad, py - rad, py + rad)
        if res is None:
            return None
        m, x0, y0 = res
        iy, ix = np.unravel_index(int(np.argmax(m)), m.shape)
        gx, gy = x0 + ix, y0 + iy
        H, W = img.shape
        th, tw = tpl.shape
        on_edge_x = (ix == 0 and gx > 0) or (ix == m.shape[1] - 1 and gx < W - tw)
        on_edge_y = (iy == 0 and gy > 0) or (iy == m.shape[0] - 1 and gy < H - th)
        if not (on_edge_x or on_edge_y):
            return m, x0, y0, int(iy), int(ix)
        px, py = gx, gy
    m, x0, y0 = res
    iy, ix = np.unravel_index(int(np.argmax(m)), m.shape)
    return m, x0, y0, int(iy), int(ix)


# ------------------------------------------------------------------ tracker
def track(
    template,
    image,
    predicted_uv,
    search_radius_px: float,
    template_center_uv=None,
    levels: Optional[int] = None,
    min_score: float = 0.6,
    min_ratio: float = 0.0,
    exclusion_px: Optional[float] = None,
    min_template_std: Optional[float] = None,
    subpixel_iterations: int = 4,
) -> TrackResult:
    """Find ``template`` in ``image`` near ``predicted_uv`` by zero-mean NCC.

    Parameters
    ----------
    template : (h, w) array, any real dtype (uint8, uint16, float)
        The window to find; at least 3x3.
    image : (H, W) array, any real dtype
        The image searched.
    predicted_uv : (2,)
        Predicted image position of the template's centre point.
    search_radius_px : float
        Half-width of the square search region around ``predicted_uv``
        (full-resolution pixels), clipped to placements where the template
        fits inside the image.
    template_center_uv : (2,), optional
        The tracked point in template pixels (may be fractional); default
        the template centre ``((w - 1) / 2, (h - 1) / 2)``.
    levels : int, optional
        Pyramid levels above full resolution (``None``: chosen from the
        search radius and template size so that the coarsest level searches
        about +-24 px and keeps the template at least 8 px wide).
    min_score : float
        Peak NCC below this -> ``ok=False`` ("no match above threshold").
    min_ratio : float
        ``score / second_score`` below this -> ``ok=False`` ("ambiguous
        match"); 0 (default) disables the test.
    exclusion_px : float, optional
        Radius around the peak within which other maxima are not counted as
        competitors (default ``max(2, min(h, w) / 4)``).
    min_template_std : float, optional
        A template whose standard deviation is below this (image units) is
        "low texture" (default :func:`default_min_std` of the template dtype).
    subpixel_iterations : int
        Resample-and-refit iterations that remove the bias of the 3x3
        quadratic peak fit (0: plain fit).

    Returns
    -------
    TrackResult
        ``uv`` in the pixel convention of ``image``.
    """
    tdtype = np.asarray(template).dtype
    tpl = as_float_image(template, "template")
    img = as_float_image(image, "image")
    th, tw = tpl.shape
    if th < 3 or tw < 3:
        raise ValueError(f"template: need at least 3x3 pixels, got {tpl.shape}")
    pred = _as_uv(predicted_uv, "predicted_uv")
    if not (np.isfinite(search_radius_px) and search_radius_px >= 0):
        raise ValueError(f"search_radius_px: must be finite and >= 0, got {search_radius_px}")
    c = np.array([(tw - 1) / 2.0, (th - 1) / 2.0]) if template_center_uv is None else _as_uv(template_center_uv, "template_center_uv")
    if min_template_std is None:
        min_template_std = default_min_std(tdtype)
    if not np.all(np.isfinite(tpl)):
        return TrackResult.failed("template contains NaN or infinity")
    if not np.all(np.isfinite(img)):
        img = np.nan_to_num(img, nan=float(np.nanmean(img)) if np.any(np.isfinite(img)) else 0.0)
    if float(tpl.std()) < min_template_std:
        return TrackResult.failed("low texture")
    if th > img.shape[0] or tw > img.shape[1]:
        return TrackResult.failed("template larger than image")
    if exclusion_px is None:
        exclusion_px = max(2.0, min(th, tw) / 4.0)
    if levels is None:
        levels = _auto_levels(search_radius_px, th, tw)
    levels = int(levels)
    if levels < 0:
        raise ValueError(f"levels: must be >= 0, got {levels}")
    # keep the coarsest template at least 3x3
    while levels > 0 and min(th, tw) / 2**levels < 3:
        levels -= 1

    # top-left placement (full resolution) of the prediction
    p0 = pred - c
    # work on a crop of the image around the search region; its origin is a
    # multiple of 2**levels so that pyramid pixel centres stay aligned
    step = 2**levels
    margin = 4 * step + 2
    H, W = img.shape
    ox = max(int(math.floor((p0[0] - search_radius_px - margin) / step)) * step, 0)
    oy = max(int(math.floor((p0[1] - search_radius_px - margin) / step)) * step, 0)
    ex = min(int(math.ceil(p0[0] + search_radius_px + tw + margin)), W)
    ey = min(int(math.ceil(p0[1] + search_radius_px + th + margin)), H)
    if ex - ox < tw or ey - oy < th:
        return TrackResult.failed("search region outside image", levels=levels)
    img = img[oy:ey, ox:ex]
    p0 = p0 - np.array([ox, oy], dtype=float)
    tpls = _pyramid(tpl - np.float32(tpl.mean()), levels)
    imgs = _pyramid(img, levels)
    s = 2.0**levels
    r_c = search_radius_px / s
    pc = p0 / s
    res = _ncc_region(
        tpls[levels], imgs[levels],
        int(math.floor(pc[0] - r_c)), int(math.ceil(pc[0] + r_c)),
        int(math.floor(pc[1] - r_c)), int(math.ceil(pc[1] + r_c)),
    )
    if res is None:
        return TrackResult.failed("search region outside image", levels=levels)
    m, x0, y0 = res
    # placements strictly within the search radius (square) at this level
    gx = x0 + np.arange(m.shape[1])
    gy = y0 + np.arange(m.shape[0])
    inside = (np.abs(gy[:, None] - pc[1]) <= r_c + 0.5) & (np.abs(gx[None, :] - pc[0]) <= r_c + 0.5)
    if float(tpls[levels].std()) < 1e-12:
        return TrackResult.failed("low texture", levels=levels)
    cands = _select_peaks(m, _N_CANDIDATES if levels > 0 else 2, max(1.0, exclusion_px / s), inside)
    if not cands:
        return TrackResult.failed("no correlation peak in the search region", levels=levels)

    refined = []
    for y, x, _ in cands:
        q = np.array([x0 + x, y0 + y], dtype=float)
        out = None
        for lev in range(levels - 1, -1, -1):
            q = 2.0 * q  # pyrDown: coarse pixel centre i sits on fine pixel centre 2 i
            out = _refine(tpls[lev], imgs[lev], np.round(q), 2)
            if out is None:
                break
            q = np.array([out[1] + out[4], out[2] + out[3]], dtype=float)
        if levels == 0:  # make sure the peak is interior (hill-climb past the search square's edge)
            out = _refine(tpls[0], imgs[0], q, 1)
        if out is not None:
            refined.append(out)
    if not refined:
        return TrackResult.failed("search region outside image", levels=levels)
    scores = [float(r[0][r[3], r[4]]) for r in refined]
    k = int(np.argmax(scores))
    best = refined[k]
    others = [(r[1] + r[4], r[2] + r[3], scores[j]) for j, r in enumerate(refined) if j != k]

    mb, bx0, by0, biy, bix = best
    score = float(mb[biy, bix])
    peak_xy = np.array([bx0 + bix, by0 + biy], dtype=float)
    # competitors: other candidates and other local maxima of the final map, outside the exclusion zone
    second = -1.0
    for cx_, cy_, osc in others:
        if (cx_ - peak_xy[0]) ** 2 + (cy_ - peak_xy[1]) ** 2 > exclusion_px**2:
            second = max(second, osc)
    ys, xs = _local_maxima(mb)
    for yy, xx in zip(ys, xs):
        if (bx0 + xx - peak_xy[0]) ** 2 + (by0 + yy - peak_xy[1]) ** 2 > exclusion_px**2:
            second = max(second, float(mb[yy, xx]))
            break
    dx, dy, sharp = subpixel_peak(mb, biy, bix)
    if subpixel_iterations > 0:
        it = _iterate_subpixel(tpls[0], img, peak_xy, (dx, dy), subpixel_iterations)
        if it is not None:
            (dx, dy), sharp, score_sub = it
            score = max(score, score_sub)
    uv = peak_xy + np.array([dx, dy]) + c + np.array([ox, oy], dtype=float)
    ratio = score / second if second > 0 else float("inf")

    ok, reason = True, ""
    on_limit = (
        abs(peak_xy[0] - p0[0]) > search_radius_px + 1.0 or abs(peak_xy[1] - p0[1]) > search_radius_px + 1.0
    )
    if score < min_score:
        ok, reason = False, f"no match above threshold (peak NCC {score:.3f} < {min_score:.3f})"
    elif on_limit:
        ok, reason = False, "peak outside the search region"
    elif ratio < min_ratio:
        ok, reason = False, f"ambiguous match (peak ratio {ratio:.3f} < {min_ratio:.3f})"
    return TrackResult(ok, reason, uv, score, second, ratio, sharp, levels)


# ---------------------------------------------------------------- windows
def extract_window(image, center_uv, half_size_px: int) -> np.ndarray:
    """A ``(2 k + 1, 2 k + 1)`` float32 window (``k = half_size_px``) centred on sub-pixel ``center_uv``.

    Bilinear resampling with ``cv2.getRectSubPix``: window pixel ``(k, k)``
    is image point ``center_uv``. Parts outside the image repeat the border
    pixels (see :func:`crop_window` for an un-resampled, clipped window).
    """
    import cv2

    img = as_float_image(image)
    c = _as_uv(center_uv, "center_uv")
    k = int(half_size_px)
    if k < 1:
        raise ValueError(f"half_size_px: must be >= 1, got {half_size_px}")
    n = 2 * k + 1
    return cv2.getRectSubPix(img, (n, n), (float(c[0]), float(c[1])))


def crop_window(image, center_uv, half_size_px: int) -> tuple[np.ndarray, np.ndarray, float]:
    """The image pixels within ``half_size_px`` of the pixel nearest ``center_uv``, clipped to the image.

    No resampling: returns ``(window (h, w) same dtype as image, center_in_window_uv (2,),
    inside_fraction)`` where ``center_in_window_uv`` is ``center_uv`` in the
    window's pixel coordinates (fractional) and ``inside_fraction`` is the
    part of the full ``(2k+1)^2`` window that lies inside the image. Use it
    as ``track(window, ..., template_center_uv=center_in_window_uv)``.
    """
    a = np.asarray(image)
    if a.ndim != 2:
        raise ValueError(f"image: expected (H, W), got shape {a.shape}")
    c = _as_uv(center_uv, "center_uv")
    k = int(half_size_px)
    if k < 1:
        raise ValueError(f"half_size_px: must be >= 1, got {half_size_px}")
    H, W = a.shape
    iu, iv = int(np.floor(c[0] + 0.5)), int(np.floor(c[1] + 0.5))
    x0, x1 = max(iu - k, 0), min(iu + k + 1, W)
    y0, y1 = max(iv - k, 0), min(iv + k + 1, H)
    if x1 <= x0 or y1 <= y0:
        return a[0:0, 0:0], c.copy(), 0.0
    frac = (x1 - x0) * (y1 - y0) / float((2 * k + 1) ** 2)
    return a[y0:y1, x0:x1], c - np.array([x0, y0], dtype=float), frac


def scale_window(window, scale: float) -> np.ndarray:
    """Resample ``window`` ``(h, w)`` by ``scale`` about its centre -> float32 ``(h', w')``.

    The output is odd-sized, ``h' = largest odd <= h * scale`` (at least 3),
    and its centre pixel is the input's centre point, with the exact scale
    (bilinear, at exact positions: :func:`scipctl.core.resample.sample_bilinear`). When shrinking, the input
    is first low-pass filtered by a Gaussian whose variance is that of the
    larger output pixel's footprint minus the input pixel's,
    ``((1/scale)^2 - 1) / 12`` px^2, which emulates area integration by the
    coarser camera (``cv2.resize(INTER_AREA)`` would round the scale to the
    integer output size).
    """
    import cv2

    w = as_float_image(window, "window")
    s = float(scale)
    if not (np.isfinite(s) and s > 0):
        raise ValueError(f"scale: must be finite and > 0, got {scale}")
    h0, w0 = w.shape

    def odd(n):
        n = int(math.floor(n + 1e-9))
        if n % 2 == 0:
            n -= 1
        return max(n, 3)

    h1, w1 = odd(h0 * s), odd(w0 * s)
    src = w
    if s < 1:
        sigma = math.sqrt(((1.0 / s) ** 2 - 1.0) / 12.0)
        if sigma > 0.05:
            src = cv2.GaussianBlur(w, (0, 0), sigma, borderType=cv2.BORDER_REPLICATE)
    cs = np.array([(w0 - 1) / 2.0, (h0 - 1) / 2.0])
    cd = np.array([(w1 - 1) / 2.0, (h1 - 1) / 2.0])
    # dst -> src map: src = (dst - cd) / s + cs, sampled at the exact positions (scipctl.core.resample)
    yd, xd = np.mgrid[0:h1, 0:w1].astype(np.float64)
    return sample_bilinear(src, (xd - cd[0]) / s + cs[0], (yd - cd[1]) / s + cs[1]).astype(np.float32)


def window_scale_for_handoff(ifov_src_rad: float, range_src_m: float, ifov_dst_rad: float, range_dst_m: float) -> float:
    """Scale factor that turns a window from the source camera into the destination camera's view.

    A target at range ``r`` seen through IFOV ``i`` (rad/px) spans ``1/(r i)``
    px per metre, so the factor is ``(r_src i_src) / (r_dst i_dst)``. Pancam
    (IFOV ~0.28 mrad) to navcam (~0.82 mrad) at the same range: ~1/3.
    """
    vals = dict(ifov_src_rad=ifov_src_rad, range_src_m=range_src_m, ifov_dst_rad=ifov_dst_rad, range_dst_m=range_dst_m)
    for k, v in vals.items():
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{k}: must be finite and > 0, got {v}")
    return float((range_src_m * ifov_src_rad) / (range_dst_m * ifov_dst_rad))
