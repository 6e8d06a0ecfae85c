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

The NCC primitives are in :mod:`scipctl.core.ncc` (NCC is invariant to an
affine intensity change of either image, so camera gain/offset differences do
not matter); templates are cut and rescaled between cameras by
:mod:`scipctl.core.windows`.

OpenCV is imported inside the functions (``scipctl --help`` stays fast).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np

from .image import as_float_image, as_uv
from .ncc import default_min_std, local_maxima, masked_template, ncc_region, refine_subpixel_peak, subpixel_peak

__all__ = ["TrackResult", "track"]

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


# ---------------------------------------------------------------- search
def _select_peaks(m: np.ndarray, k: int, sep: float, valid: Optional[np.ndarray] = None) -> list[tuple[int, int, float]]:
    """Up to ``k`` local maxima of ``m``, strongest first, pairwise farther apart than ``sep`` px."""
    ys, xs = local_maxima(m, valid)
    out: list[tuple[int, int, float]] = []
    for y, x in zip(ys, xs):
        if all((y - y2) ** 2 + (x - x2) ** 2 > sep * sep for y2, x2, _ in out):
            out.append((int(y), int(x), float(m[y, x])))
            if len(out) >= k:
                break
    return out


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


def _refine(tpl, img, p_xy, rad: int, max_moves: int = 4, mask=None):
    """Hill-climb a local NCC search of radius ``rad`` around integer top-left ``p_xy`` (``mask``: the template's
    counted pixels, :func:`~scipctl.core.ncc.ncc_region`).

    Returns ``(map, x0, y0, iy, ix)`` of the local map containing the peak in
    its interior (or on the image-clipped border), or ``None``.
    """
    px, py = int(p_xy[0]), int(p_xy[1])
    res = None
    for _ in range(max_moves):
        res = ncc_region(tpl, img, px - rad, px + rad, py - rad, py + rad, mask=mask)
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
    accept_border_peak: bool = True,
    template_mask=None,
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
    accept_border_peak : bool
        ``False``: a peak where the template touches the image's edge (the
        last placement inside the image) is ``ok=False`` ("peak at the image
        border"), since the correlation may still rise towards a match that
        lies partly outside the image. For whole templates (rendered or
        warped windows); a window clipped at the image's edge
        (:func:`~scipctl.core.windows.crop_window`) belongs there, hence the
        default ``True``.
    template_mask : (h, w) bool array, optional
        The template pixels that count (True); the NCC then takes the
        means and norms of the template and of each image window over
        those pixels only (e.g. a rendered template's pixels that lie off
        the surface it was rendered through,
        :mod:`scipctl.core.relief_mask`). None: every pixel counts.

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
    pred = as_uv(predicted_uv, "predicted_uv")
    if not (np.isfinite(search_radius_px) and search_radius_px >= 0):
        raise ValueError(f"search_radius_px: must be finite and >= 0, got {search_radius_px}")
    c = np.array([(tw - 1) / 2.0, (th - 1) / 2.0]) if template_center_uv is None else as_uv(template_center_uv, "template_center_uv")
    if min_template_std is None:
        min_template_std = default_min_std(tdtype)
    if not np.all(np.isfinite(tpl)):
        return TrackResult.failed("template contains NaN or infinity")
    if not np.all(np.isfinite(img)):
        img = np.nan_to_num(img, nan=float(np.nanmean(img)) if np.any(np.isfinite(img)) else 0.0)
    keep = None
    if template_mask is not None:
        keep = np.asarray(template_mask)
        if keep.shape != tpl.shape or keep.dtype != bool:
            raise ValueError(f"template_mask: bool {tpl.shape} expected, got {keep.dtype} {keep.shape}")
        if keep.sum() < 9:
            return TrackResult.failed("template mask keeps fewer than 9 pixels")
    if float(tpl.std() if keep is None else tpl[keep].std()) < min_template_std:
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
    if keep is None:
        tpls = _pyramid(tpl - np.float32(tpl.mean()), levels)
        masks = [None] * (levels + 1)
    else:
        # the masked template is 0 off the mask; a coarser level counts the pixels that are mostly kept
        t0, m0 = masked_template(tpl, keep)
        tpls = _pyramid(t0, levels)
        masks = [m0] + [(m >= 0.5).astype(np.uint8) for m in _pyramid(m0.astype(np.float32), levels)[1:]]
        while levels > 0 and int(masks[levels].sum()) < 9:
            levels -= 1
        tpls, masks = tpls[:levels + 1], masks[:levels + 1]
    imgs = _pyramid(img, levels)
    s = 2.0**levels
    r_c = search_radius_px / s
    pc = p0 / s
    res = ncc_region(
        tpls[levels], imgs[levels],
        int(math.floor(pc[0] - r_c)), int(math.ceil(pc[0] + r_c)),
        int(math.floor(pc[1] - r_c)), int(math.ceil(pc[1] + r_c)), mask=masks[levels],
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
            out = _refine(tpls[lev], imgs[lev], np.round(q), 2, mask=masks[lev])
            if out is None:
                break
            q = np.array([out[1] + out[4], out[2] + out[3]], dtype=float)
        if levels == 0:  # make sure the peak is interior (hill-climb past the search square's edge)
            out = _refine(tpls[0], imgs[0], q, 1, mask=masks[0])
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
    ys, xs = local_maxima(mb)
    for yy, xx in zip(ys, xs):
        if (bx0 + xx - peak_xy[0]) ** 2 + (by0 + yy - peak_xy[1]) ** 2 > exclusion_px**2:
            second = max(second, float(mb[yy, xx]))
            break
    dx, dy, sharp = subpixel_peak(mb, biy, bix)
    if subpixel_iterations > 0:
        it = refine_subpixel_peak(tpls[0], img, peak_xy, (dx, dy), subpixel_iterations, mask=masks[0])
        if it is not None:
            (dx, dy), sharp, score_sub = it
            score = max(score, score_sub)
    uv = peak_xy + np.array([dx, dy]) + c + np.array([ox, oy], dtype=float)
    ratio = score / second if second > 0 else float("inf")

    ok, reason = True, ""
    on_limit = (
        abs(peak_xy[0] - p0[0]) > search_radius_px + 1.0 or abs(peak_xy[1] - p0[1]) > search_radius_px + 1.0
    )
    # for a whole template, a maximum where it touches the image's edge is the end of the placements, not a peak:
    # the NCC surface may still be rising towards a match that lies partly outside the image (a target 2.5 px from
    # the edge of a 41 px pancam window was "found" 17 px inside it; docs/stereo-and-tracking.md, "Reproducibility")
    place = peak_xy + np.array([ox, oy], dtype=float)
    at_border = not accept_border_peak and (place[0] <= 0 or place[1] <= 0 or place[0] >= W - tw or place[1] >= H - th)
    if score < min_score:
        ok, reason = False, f"no match above threshold (peak NCC {score:.3f} < {min_score:.3f})"
    elif on_limit:
        ok, reason = False, "peak outside the search region"
    elif at_border:
        ok, reason = False, "peak at the image border (the match may lie beyond it)"
    elif ratio < min_ratio:
        ok, reason = False, f"ambiguous match (peak ratio {ratio:.3f} < {min_ratio:.3f})"
    return TrackResult(ok, reason, uv, score, second, ratio, sharp, levels)
