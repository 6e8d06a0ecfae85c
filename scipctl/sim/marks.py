"""Exact marks: the projection of a target's true 3-D point through the true model of every image that sees it.

Seen = in the image, and not occluded (checked by a ray cast from the model's ray origin -- the
CAHVORE entrance pupil -- to the point). Points ``(K, 3)`` site frame metres; ``uv`` ``(K, 2)`` pixels.
"""

from __future__ import annotations

import numpy as np

from ..core.camera import CameraModel
from ..model import Mark, TargetMarks
from .scene import Scene

OCCLUSION_TOL_M = 1e-3


def project_visible(scene: Scene, model_site: CameraModel, width: int, height: int, X_site, tol_m: float = OCCLUSION_TOL_M):
    """Project points ``X_site`` ``(K, 3)``; ``(uv (K, 2), visible (K,) bool)``.

    Visible = finite projection inside ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``, and the ray from the model's
    origin for that pixel (the CAHVORE entrance pupil moves with the ray) towards the point first hits the
    surface at the point (within ``tol_m``): nothing in front of it, and the ray does not slip past it
    (a point exactly on a silhouette).
    """
    X = np.asarray(X_site, float).reshape(-1, 3)
    uv = model_site.project(X)
    ok = np.all(np.isfinite(uv), axis=1)
    ok &= (uv[:, 0] >= -0.5) & (uv[:, 0] <= width - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] <= height - 0.5)
    vis = np.zeros(len(X), bool)
    idx = np.flatnonzero(ok)
    if len(idx):
        o, _ = model_site.unproject(uv[idx])
        v = X[idx] - o
        dist = np.linalg.norm(v, axis=1)
        hits = scene.cast(o, v / dist[:, None])
        vis[idx] = np.abs(hits.t_m - dist) <= tol_m  # the first hit is the point itself
    return uv, vis


def compute_marks(scene: Scene, products: list, targets: list) -> list[TargetMarks]:
    """Exact marks of every target in every product that sees it (``sigma_px`` 0)."""
    out = []
    X = np.array([t.xyz_site_m for t in targets]).reshape(-1, 3)
    vis_all = []
    for p in products:
        T_rover_site = p.T_site_rover_true.inverse()
        uv = p.model_true.project(T_rover_site.apply(X))  # true model, true rover frame: the definition of a mark
        _, vis = project_visible(scene, p.model_true_site, p.width, p.height, X)
        vis_all.append((p.product_id, uv, vis))
    for j, t in enumerate(targets):
        marks = [Mark(pid, float(uv[j, 0]), float(uv[j, 1]), 0.0) for pid, uv, vis in vis_all if vis[j]]
        out.append(TargetMarks(t.id, t.kind, t.description, marks))
    return out
