"""Zero-mean normalised cross-correlation (NCC) of image windows and its peaks (pure numerics).

Pixel convention (docs/conventions.md): ``(u, v)`` = (column, row), 0-based,
``(0, 0)`` is the centre of the top-left pixel; an image is indexed
``img[v, u]``. An NCC map ``m`` of a template ``(h, w)`` over an image
``(H, W)`` is ``(H - h + 1, W - w + 1)``; ``m[y, x]`` scores the template with
its top-left pixel on image pixel ``(u=x, v=y)``.

The correlation is OpenCV's ``matchTemplate`` with ``TM_CCOEFF_NORMED`` on
float32 (:func:`ncc_map`, :func:`ncc_region`). Peaks: :func:`local_maxima`
(3x3), :func:`subpixel_peak` (quadratic fit to the 3x3 neighbourhood, with the
peak sharpness: smallest curvature of the NCC surface at the peak, per px^2;
~0 along an edge) and :func:`refine_subpixel_peak` (resample-and-refit, which
removes the bias of the plain fit). :func:`default_min_std` is the texture
threshold below which a window's NCC is meaningless.

NCC is invariant to an affine intensity change ``a * I + b`` (``a > 0``) of
either image, so camera gain/offset differences do not matter.

Used by the tracker (:mod:`scipctl.core.tracking`) and point stereo
(:mod:`scipctl.core.point_stereo`). OpenCV is imported inside the functions
(``scipctl --help`` stays fast).
"""

from __future__ import annotations

from typing import Optional

import numpy as np

from .image import as_float_image
from .resample import sample_bicubic_grids

__all__ = [
    "default_min_std",
    "ncc_map",
    "ncc_region",
    "local_maxima",
    "subpixel_peak",
    "refine_subpixel_peak",
]


def default_min_std(dtype) -> float:
    """Default texture threshold (std of a window, in the image's own units).

    Integer images: half a digital number (a window varying by less than half
    a quantum is flat). Float images: ``1e-6`` (only an exactly flat window).
    """
    return 0.5 if np.dtype(dtype).kind in "ui" else 1e-6


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


def refine_subpixel_peak(tpl: np.ndarray, img: np.ndarray, peak_xy, d0, iterations: int = 4,
                         mask: Optional[np.ndarray] = None):
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
    edge pixels. ``mask``: the template pixels that count (``uint8`` (th, tw),
    nonzero: counted; :func:`masked_template`); None: all.
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
    # the patch shifted by (du, dv) is sample_bicubic(crop, gx + pad + du, gy + pad + dv) on the (th, tw) grid;
    # a 3x3 step's nine patches (three column and three row shifts) are sampled at once, bit for bit the same
    gx = np.arange(tw, dtype=np.float64) + pad
    gy = np.arange(th, dtype=np.float64) + pad

    def shifted(dus, dvs):  # (len(dvs), len(dus), th, tw) float32: [j, i] shifted by (dus[i], dvs[j])
        return sample_bicubic_grids(crop, gx + np.array(dus)[:, None], gy + np.array(dvs)[:, None]).astype(np.float32)

    d = np.array(d0, dtype=float)
    sharp = 0.0
    for it in range(iterations):
        h = 1.0 / 2 ** min(it, 2)
        m3 = np.empty((3, 3))
        patches = shifted([d[0] + (i - 1) * h for i in range(3)], [d[1] + (j - 1) * h for j in range(3)])
        for j in range(3):
            for i in range(3):
                m3[j, i] = cv2.matchTemplate(patches[j, i], tpl, cv2.TM_CCOEFF_NORMED, mask=mask)[0, 0]
        dx, dy, sharp = subpixel_peak(m3, 1, 1)
        sharp /= h * h
        d += (dx * h, dy * h)
        if np.any(np.abs(d) > 1.0):
            return None
        if h <= 0.25 and abs(dx * h) < 1e-3 and abs(dy * h) < 1e-3:
            break
    patch = shifted([d[0]], [d[1]])[0, 0]
    score = float(cv2.matchTemplate(patch, tpl, cv2.TM_CCOEFF_NORMED, mask=mask)[0, 0])
    return d, sharp, score


def local_maxima(m: np.ndarray, valid: Optional[np.ndarray] = None) -> tuple[np.ndarray, np.ndarray]:
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


def ncc_region(tpl: np.ndarray, img: np.ndarray, x0: int, x1: int, y0: int, y1: int,
               mask: Optional[np.ndarray] = None):
    """NCC for top-left placements ``x0..x1``, ``y0..y1`` (inclusive), clipped to the image.

    ``mask``: the template pixels that count (``uint8`` (th, tw), nonzero: counted; the means and norms of
    both windows are then taken over those pixels only, :func:`masked_template`); None: all.
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
    return cv2.matchTemplate(crop, tpl, cv2.TM_CCOEFF_NORMED, mask=mask), x0c, y0c


def masked_template(tpl: np.ndarray, keep: np.ndarray):
    """A template whose pixels ``keep`` (bool (th, tw)) alone count in the NCC: ``(template, mask)``, the template
    zero-mean over the kept pixels and 0 elsewhere (float32), the mask ``uint8`` (1: kept) as OpenCV's
    ``matchTemplate`` takes it (with ``TM_CCOEFF_NORMED`` it takes each window's mean and norm over the kept pixels,
    OpenCV 4.x and 5.x alike). Raises ValueError on a shape mismatch or when nothing is kept."""
    t = as_float_image(tpl, "template")
    k = np.asarray(keep)
    if k.shape != t.shape or k.dtype != bool:
        raise ValueError(f"keep: bool {t.shape} expected, got {k.dtype} {k.shape}")
    if not k.any():
        raise ValueError("keep: no template pixel kept")
    t = np.where(k, t - np.float32(t[k].mean()), np.float32(0.0)).astype(np.float32)
    return t, k.astype(np.uint8)
