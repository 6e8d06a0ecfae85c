"""Triangulation: closest approach of two rays (pure numerics).

Rays are ``o + t d`` in any common frame (origins and directions ``(..., 3)``);
see :func:`triangulate_rays`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["triangulate_rays"]


def triangulate_rays(o1, d1, o2, d2):
    """Closest approach of two rays (vectorised).

    ``o1, d1, o2, d2`` are ``(..., 3)`` (broadcastable) origins and
    directions (any length; the ray parameters are in units of ``|d|``).
    Returns ``(midpoint (..., 3), miss_distance (...,), t (..., 2))`` where
    ``o1 + t[..., 0] d1`` and ``o2 + t[..., 1] d2`` are the closest points and
    the midpoint is halfway between them. Parallel rays give NaN.
    """
    arrs = [np.asarray(x, dtype=float) for x in (o1, d1, o2, d2)]
    for name, a in zip(("o1", "d1", "o2", "d2"), arrs):
        if a.shape[-1:] != (3,):
            raise ValueError(f"{name}: expected shape (..., 3), got {a.shape}")
    o1, d1, o2, d2 = np.broadcast_arrays(*arrs)
    w0 = o1 - o2
    a = np.sum(d1 * d1, -1)
    b = np.sum(d1 * d2, -1)
    c = np.sum(d2 * d2, -1)
    d = np.sum(d1 * w0, -1)
    e = np.sum(d2 * w0, -1)
    den = a * c - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        par = den <= 1e-14 * a * c
        den = np.where(par, np.nan, den)
        t1 = (b * e - c * d) / den
        t2 = (a * e - b * d) / den
    p1 = o1 + t1[..., None] * d1
    p2 = o2 + t2[..., None] * d2
    mid = 0.5 * (p1 + p2)
    miss = np.linalg.norm(p1 - p2, axis=-1)
    return mid, miss, np.stack([t1, t2], -1)
