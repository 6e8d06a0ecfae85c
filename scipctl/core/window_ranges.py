"""Does a point-stereo window straddle a depth edge? Its point range against the window's dense ranges (pure numerics).

Point stereo (:mod:`scipctl.core.point_stereo`) correlates a whole window around the designated pixel; when the
window holds a nearer (or farther) surface with more texture than the target's, the match can take that surface's
disparity while its score stays high (docs/stereo-and-tracking.md, "Four later blind populations": a rock edge
0.6 m in front of a sand target, matched at NCC 0.95 and 0.99). Dense stereo of the same pair sees each pixel on
its own, so the median of its ranges over the window says where most of the window is; a point range far from it
says the window was split and point stereo may have taken the wrong side.

Frames: ranges are distances from the left camera's ``C`` in the camera models' frame (metres). Pixels follow
docs/conventions.md (``(u, v)``, ``(0, 0)`` the centre of the top-left pixel).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["MIN_WINDOW_POINTS", "window_pixels", "window_range_gap"]

#: fewer valid dense-stereo pixels than this in the window: no gap (NaN); the median of a handful says little
MIN_WINDOW_POINTS = 10


def window_pixels(uv, window_px: int) -> np.ndarray:
    """The ``(window_px**2, 2)`` pixel centres ``(u, v)`` of the square window of side ``window_px`` (odd) that point
    stereo correlates around ``uv`` ``(2,)``: centred on the nearest pixel, as :func:`~scipctl.core.windows.crop_window`
    cuts it. Pixels outside the image are the caller's to drop (dense stereo gives NaN there)."""
    uv = np.asarray(uv, float)
    if uv.shape != (2,) or not np.all(np.isfinite(uv)):
        raise ValueError(f"uv: expected a finite (2,), got {uv!r}")
    window_px = int(window_px)
    if window_px < 1 or window_px % 2 == 0:
        raise ValueError(f"window_px: expected an odd size >= 1, got {window_px}")
    h = window_px // 2
    cu, cv = np.floor(uv + 0.5)
    du, dv = np.meshgrid(np.arange(-h, h + 1, dtype=float), np.arange(-h, h + 1, dtype=float))
    return np.stack([cu + du.ravel(), cv + dv.ravel()], axis=1)


def window_range_gap(range_window_m, point_range_m: float, min_points: int = MIN_WINDOW_POINTS) -> tuple[float, int]:
    """``(gap, n)``: ``|point_range_m - median(range_window_m)| / point_range_m`` (a fraction of the range) over the
    ``n`` finite, positive ranges of ``range_window_m`` ``(N,)`` (m; NaN where dense stereo has none); ``gap`` is NaN
    when ``n < min_points`` or the point range is not a positive number."""
    r = np.asarray(range_window_m, float).ravel()
    r = r[np.isfinite(r) & (r > 0)]
    n = int(r.size)
    point_range_m = float(point_range_m)
    if n < int(min_points) or not (math.isfinite(point_range_m) and point_range_m > 0):
        return math.nan, n
    return abs(point_range_m - float(np.median(r))) / point_range_m, n
