"""Image windows (templates): cut out, crop, and rescale between cameras (pure numerics).

Pixel convention (docs/conventions.md): ``(u, v)`` = (column, row), 0-based,
``(0, 0)`` is the centre of the top-left pixel; an image is indexed
``img[v, u]``. Every ``uv`` here is a ``(2,)`` float array in that convention.

Camera changes (pancam -> navcam handoff, far navcam -> hazcam): a target
seen at range ``r`` through IFOV ``i`` (rad/px) spans ``1 / (r * i)`` pixels
per metre, so a window taken in one camera is shrunk or enlarged by
:func:`window_scale_for_handoff` with :func:`scale_window` before tracking
(:func:`scipctl.core.tracking.track`).

OpenCV is imported inside the functions (``scipctl --help`` stays fast).
"""

from __future__ import annotations

import math

import numpy as np

from .image import as_float_image, as_uv
from .resample import sample_bilinear

__all__ = ["extract_window", "crop_window", "scale_window", "window_scale_for_handoff"]


def extract_window(image, center_uv, half_size_px: int) -> np.ndarray:
    """A ``(2 k + 1, 2 k + 1)`` float32 window (``k = half_size_px``) centred on sub-pixel ``center_uv``.

    Bilinear resampling with ``cv2.getRectSubPix``: window pixel ``(k, k)``
    is image point ``center_uv``. Parts outside the image repeat the border
    pixels (see :func:`crop_window` for an un-resampled, clipped window).
    """
    import cv2

    img = as_float_image(image)
    c = as_uv(center_uv, "center_uv")
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
    c = as_uv(center_uv, "center_uv")
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


def filtered_crop(image, center_uv, reach_px: int, margin_px: int, filt, align: int = 64):
    """The part of ``image`` (H, W) within ``reach_px + margin_px`` of the pixel nearest ``center_uv`` (2,), passed
    through ``filt`` (a float32 (h, w) array -> one of the same shape, e.g. a blur or a median with the edges
    replicated; ``margin_px`` at least its radius, so that the pixels within ``reach_px`` see no crop edge that is not
    the image's), as ``(crop float32 (h, w), origin_uv (2,))``: image pixel = crop pixel + origin; ``(None, origin)``
    when that region lies wholly outside the image. The origin is a multiple of ``align`` (a tracker's pyramid stays
    aligned with the whole image's)."""
    img = np.asarray(image, np.float32)
    if img.ndim != 2:
        raise ValueError(f"image: expected (H, W), got shape {img.shape}")
    H, W = img.shape
    c = np.round(np.asarray(center_uv, float))
    if c.shape != (2,) or not np.all(np.isfinite(c)):
        raise ValueError(f"center_uv: expected 2 finite numbers, got {center_uv!r}")
    m = int(reach_px) + int(margin_px)
    u0 = max(0, (int(c[0]) - m) // align * align)
    v0 = max(0, (int(c[1]) - m) // align * align)
    u1 = min(W, int(c[0]) + m + 1)
    v1 = min(H, int(c[1]) + m + 1)
    if u1 <= u0 or v1 <= v0:
        return None, np.array([u0, v0], float)
    return filt(np.ascontiguousarray(img[v0:v1, u0:u1])), np.array([u0, v0], float)


def median_image(image, size_px: int) -> np.ndarray:
    """``image`` (h, w) median-filtered over ``size_px`` x ``size_px`` pixels (an odd size >= 3; edges replicated),
    float32: an isolated speck narrower than half the window is replaced by its surroundings, an edge is kept."""
    from scipy.ndimage import median_filter

    k = int(size_px)
    if k < 3 or k % 2 == 0 or k != size_px:
        raise ValueError(f"size_px: must be an odd integer >= 3, got {size_px!r}")
    return median_filter(np.asarray(image, np.float32), size=k, mode="nearest")


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
