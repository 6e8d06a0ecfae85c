"""Epipolar geometry of a stereo pair of CAHV/CAHVOR/CAHVORE models (pure numerics).

Frames: every 3-D quantity is in the frame of the camera models passed in
(for downlink products, the rover frame at acquisition). Pixels follow
docs/conventions.md: ``(u, v)`` = (column, row), ``(0, 0)`` the centre of the
top-left pixel.

For CAHVOR/CAHVORE models the epipolar "line" of a left pixel is a curve: we
unproject the left pixel to a ray (:func:`pixel_ray`) and project points on it
at ranges ``min_range_m .. max_range_m`` through the right model
(:func:`epipolar_curve`). :func:`polyline_foot` finds the nearest point of such
a curve to a right-image pixel (the signed distance from the curve is a
calibration-health figure, see :func:`scipctl.core.point_stereo.point_stereo`).
"""

from __future__ import annotations

import math

import numpy as np

from .camera import CameraModel, check_camera_model

__all__ = ["epipolar_curve", "pixel_ray", "polyline_foot"]


def epipolar_curve(
    left_model: CameraModel,
    right_model: CameraModel,
    uv_left,
    min_range_m: float,
    max_range_m: float,
    max_step_px: float = 0.5,
    max_points: int = 20000,
) -> tuple[np.ndarray, np.ndarray]:
    """The epipolar curve of left pixel ``uv_left`` (2,) in the right image.

    Points ``o + r d`` on the left pixel's ray, ``r`` from ``max_range_m``
    down to ``min_range_m`` (uniform in ``1/r``, refined until consecutive
    points are at most ``max_step_px`` apart), projected through the right
    model. Returns ``(uv (N, 2), range_m (N,))``, points that do not project
    (behind the right camera) removed.
    """
    check_camera_model(left_model, "left_model")
    check_camera_model(right_model, "right_model")
    if not (0 < min_range_m < max_range_m and np.isfinite(max_range_m)):
        raise ValueError(f"ranges: need 0 < min_range_m < max_range_m < inf, got {min_range_m}, {max_range_m}")
    uv = np.asarray(uv_left, dtype=float).reshape(2)
    o, d = pixel_ray(left_model, uv)
    n = 64
    while True:
        inv = np.linspace(1.0 / max_range_m, 1.0 / min_range_m, n)
        r = 1.0 / inv
        c = right_model.project(o[None, :] + r[:, None] * d[None, :])
        good = np.all(np.isfinite(c), axis=1)
        c, r = c[good], r[good]
        if len(c) < 2:
            return c, r
        step = float(np.max(np.linalg.norm(np.diff(c, axis=0), axis=1)))
        if step <= max_step_px or n >= max_points:
            return c, r
        n = int(min(max_points, math.ceil(n * step / max_step_px * 1.1) + 2))


def pixel_ray(model: CameraModel, uv) -> tuple[np.ndarray, np.ndarray]:
    """Ray ``(origin (3,), unit direction (3,))`` of one pixel ``uv`` (2,)."""
    o, d = model.unproject(np.asarray(uv, dtype=float).reshape(1, 2))
    return o[0], d[0]


def polyline_foot(curve: np.ndarray, p: np.ndarray):
    """Nearest point of polyline ``curve`` (N, 2) to ``p`` (2,): ``(foot, unit tangent, segment index, t)``."""
    a = curve[:-1]
    b = curve[1:]
    ab = b - a
    L2 = np.sum(ab * ab, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.clip(np.sum((p - a) * ab, 1) / L2, 0.0, 1.0)
    t = np.where(L2 > 0, t, 0.0)
    q = a + t[:, None] * ab
    dist = np.linalg.norm(q - p, axis=1)
    k = int(np.argmin(dist))
    # tangent from a few segments around the foot (robust to tiny segments)
    k0, k1 = max(k - 2, 0), min(k + 3, len(curve) - 1)
    tan = curve[k1] - curve[k0]
    tan = tan / max(np.linalg.norm(tan), 1e-12)
    return q[k], tan, k, float(t[k])
