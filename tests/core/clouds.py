"""Synthetic terrain point clouds with exact truth, shared by the registration tests (tests/core/
test_registration.py, test_global_registration.py, test_registration_check.py).

The terrain is rolling ground with a few dome-shaped rocks (rover frame, z down: rocks have negative z), so that
registering two samplings of it is well posed in all six degrees of freedom; :func:`flat` is a plane with no
relief, where sliding along the plane is invisible to geometry.
"""

from __future__ import annotations

import numpy as np

ROCKS = ((1.5, 0.3, 0.25), (2.4, -0.6, 0.35), (1.1, -0.9, 0.2), (3.0, 0.8, 0.3))  # (x, y, radius) m


def terrain(seed: int = 0, n: int = 60000, lo=(0.5, -1.5), hi=(3.5, 1.5), rocks=ROCKS) -> np.ndarray:
    """``(n, 3)`` points of the terrain, sampled uniformly in x-y within ``lo``-``hi`` (a different ``seed``
    gives a different sampling of the same surface)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(lo, hi, size=(n, 2))
    z = 0.05 * np.sin(2.1 * xy[:, 0]) * np.cos(1.7 * xy[:, 1]) + 0.02 * np.sin(7 * xy[:, 0] + 3 * xy[:, 1])
    for cx, cy, r in rocks:
        d2 = (xy[:, 0] - cx) ** 2 + (xy[:, 1] - cy) ** 2
        z = z - np.where(d2 < r * r, np.sqrt(np.maximum(r * r - d2, 0)) * 0.8, 0)
    return np.column_stack([xy, z])


def flat(seed: int = 0, n: int = 60000, lo=(0.5, -1.5), hi=(3.5, 1.5)) -> np.ndarray:
    """``(n, 3)`` points of the plane z = 0 (no relief)."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(lo, hi, size=(n, 2)), np.zeros(n)])


CAMERA_M = np.array([0.0, 0.0, -1.0])  # the clouds' sensor: 1 m above the ground (z down)


def far_pair(T_target_source, seed_source: int = 1):
    """Target terrain (sampling 0), the source (sampling ``seed_source``) moved by ``T_target_source``'s
    inverse, and the source's camera in the source frame: ``(target (N, 3), source (M, 3), camera (3,))``."""
    return (terrain(0), T_target_source.inverse().apply(terrain(seed_source)),
            T_target_source.inverse().apply(CAMERA_M[None])[0])
