"""Extra targets for a simulated run: random true surface points near the target rock, seen by given images,
with exact marks (pure numerics, no files).

They multiply the handoff cases one rendering gives (the trust model of ``scip`` is fitted on them, see
docs/handoff.md "Trust: scip"): every point is on the true surface (a ray cast of the reference image's true
model), within ``max_radius_m`` of the rock's centre (where the scenarios' own targets are), and visible (in the
image, not occluded) in every one of the ``required`` images; its marks are :func:`~scipctl.sim.marks.compute_marks`'s.

:func:`choose_occluded_targets` picks the opposite case, the one a handoff must refuse: true surface points that
the navcams see but that something else (a rock, the rock's own bulk) hides from the hazcam that answers, at least
``min_depth_m`` in front of the point along the hazcam's ray. No hazcam answer can be right for such a target.
"""

from __future__ import annotations

import numpy as np

from ..model import TargetMarks
from .marks import compute_marks, project_visible
from .scene import Scene
from .targets import Target

EXTRA_KIND = "extra"
OCCLUDED_KIND = "occluded"
STEP_M = 1e-3  # a ray cast again starts this far past the last hit (past the surface it met)
MAX_LAYERS = 4  # surfaces passed along one hazcam ray before giving up
# an occluded target is hidden over a disk of this radius (hazcam px) around its pixel: no answer within the
# issue's success radius (4 px) can show the target's own surface (a point just behind a silhouette is not hidden
# for an answer one pixel over); checked on the centre and on rings of 2 and 4 px, 8 rays each
HIDDEN_DISK_PX = 4.0
RING_OFFSETS_PX = np.array([[0.0, 0.0]] + [[r * np.cos(a), r * np.sin(a)] for r in (0.5 * HIDDEN_DISK_PX, HIDDEN_DISK_PX)
                                            for a in np.arange(8) * np.pi / 4])


def inner_pixels(rng: np.random.Generator, width: int, height: int, inner_frac: float, k: int) -> np.ndarray:
    """``k`` uniform pixels ``(k, 2)`` of an image's inner ``1 - 2 inner_frac`` part (u drawn first, then v)."""
    return np.stack([rng.uniform(inner_frac * width, (1 - inner_frac) * width, k),
                     rng.uniform(inner_frac * height, (1 - inner_frac) * height, k)], 1)


def in_inner_part(uv: np.ndarray, width: int, height: int, inner_frac: float) -> np.ndarray:
    """``(K,)`` bool: pixels ``uv`` ``(K, 2)`` strictly inside the image's inner ``1 - 2 inner_frac`` part."""
    f = inner_frac
    return ((uv[:, 0] > f * width) & (uv[:, 0] < (1 - f) * width) & (uv[:, 1] > f * height) & (uv[:, 1] < (1 - f) * height))


def choose_extra_targets(scene: Scene, products: list, ref_id: str, required_ids: list, n: int,
                         rng: np.random.Generator, max_radius_m: float = 1.5, inner_frac: float = 0.06,
                         id_prefix: str = "x") -> list[Target]:
    """Up to ``n`` :class:`~scipctl.sim.targets.Target` (kind ``"extra"``), ids ``x01``, ``x02``...

    ``products``: the run's :class:`~scipctl.sim.products.ProductPlan` list; ``ref_id``: the image whose
    pixels are sampled (uniformly over its inner ``1 - 2 inner_frac`` part; the near left hazcam in practice);
    ``required_ids``: the images that must see each point inside the same inner part. Site frame, metres.
    """
    by = {p.product_id: p for p in products}
    ref = by[ref_id]
    uv = inner_pixels(rng, ref.width, ref.height, inner_frac, max(20 * n, 200))
    o, d = ref.model_true_site.unproject(uv)
    hits = scene.cast(o, d)
    ok = hits.hit & (np.hypot(hits.points[:, 0], hits.points[:, 1]) < max_radius_m)
    X = np.where(ok[:, None], hits.points, 0.0)
    for pid in [ref_id] + list(required_ids):
        p = by[pid]
        uvk, vis = project_visible(scene, p.model_true_site, p.width, p.height, X)
        ok &= vis & in_inner_part(uvk, p.width, p.height, inner_frac)
    idx = np.flatnonzero(ok)[:n]
    return [Target(f"{id_prefix}{i + 1:02d}", EXTRA_KIND, "random visible surface point (trust-model data)",
                   np.asarray(X[j], float)) for i, j in enumerate(idx)]


def choose_occluded_targets(scene: Scene, products: list, hazcam_id: str, seen_ids: list, n: int,
                            rng: np.random.Generator, max_radius_m: float = 1.5, inner_frac: float = 0.06,
                            min_depth_m: float = 0.05, id_prefix: str = "o") -> list[tuple]:
    """Up to ``n`` targets hidden from the image ``hazcam_id`` and seen by every image of ``seen_ids``.

    Rays of ``hazcam_id``'s true model through uniform pixels of its inner ``1 - 2 inner_frac`` part are followed
    past their first hit (the occluder) to the first surface at least ``min_depth_m`` behind it (site frame,
    metres; casting again :data:`STEP_M` past each hit, at most :data:`MAX_LAYERS` times). Such a point projects
    to the ray's pixel and is hidden there; it is kept when it lies within ``max_radius_m`` of the rock's centre,
    stays hidden over the disk of :data:`HIDDEN_DISK_PX` around its pixel (every ray of the disk's rings first
    hits a surface at least ``min_depth_m`` nearer than the point) and every image of ``seen_ids`` sees it (in
    the inner part, not occluded: :func:`project_visible`).

    Returns ``[(Target (kind "occluded", ids o01, o02...), occluder depth m, hazcam pixel (2,))]``.
    """
    by = {p.product_id: p for p in products}
    hz = by[hazcam_id]
    k = max(100 * n, 3000)
    uv = inner_pixels(rng, hz.width, hz.height, inner_frac, k)
    o, d = hz.model_true_site.unproject(uv)
    first = scene.cast(o, d)
    t_first = np.where(first.hit, first.t_m, np.inf)
    X = np.full((k, 3), np.nan)
    depth = np.full(k, np.nan)
    t_prev = t_first.copy()
    todo = np.isfinite(t_prev)
    for _ in range(MAX_LAYERS):
        idx = np.flatnonzero(todo)
        if not len(idx):
            break
        t0 = t_prev[idx] + STEP_M
        h = scene.cast(o[idx] + t0[:, None] * d[idx], d[idx])
        t_hit = np.where(h.hit, t0 + h.t_m, np.inf)
        deep = np.isfinite(t_hit) & (t_hit - t_first[idx] >= min_depth_m)
        X[idx[deep]] = h.points[deep]
        depth[idx[deep]] = (t_hit - t_first[idx])[deep]
        todo[idx[deep | ~np.isfinite(t_hit)]] = False
        t_prev[idx] = t_hit
    ok = np.isfinite(depth) & (np.hypot(X[:, 0], X[:, 1]) < max_radius_m)
    idx = np.flatnonzero(ok)
    if len(idx):  # hidden over the whole disk: each ring ray meets a surface min_depth_m nearer than the point
        m = len(RING_OFFSETS_PX)
        uv_ring = (uv[idx, None, :] + RING_OFFSETS_PX[None]).reshape(-1, 2)
        o_r, d_r = hz.model_true_site.unproject(uv_ring)
        t_r = scene.cast(o_r, d_r).t_m.reshape(len(idx), m)
        dist = np.linalg.norm(X[idx, None, :] - o_r.reshape(len(idx), m, 3), axis=2)
        ok[idx] = np.all(t_r <= dist - min_depth_m, axis=1)
    Xq = np.where(ok[:, None], X, 0.0)
    for pid in seen_ids:
        p = by[pid]
        uvk, vis = project_visible(scene, p.model_true_site, p.width, p.height, Xq)
        ok &= vis & in_inner_part(uvk, p.width, p.height, inner_frac)
    idx = np.flatnonzero(ok)[:n]
    return [(Target(f"{id_prefix}{i + 1:02d}", OCCLUDED_KIND, "surface point the navcams see and the hazcam does not "
                    "(trust-model data)", np.asarray(X[j], float)), float(depth[j]), uv[j].copy())
            for i, j in enumerate(idx)]


def extra_marks(scene: Scene, products: list, targets: list[Target]) -> list[TargetMarks]:
    """Exact marks of ``targets`` in every product that sees them."""
    return compute_marks(scene, products, targets) if targets else []
