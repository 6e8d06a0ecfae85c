"""Shallow occluders: a pebble set down a few centimetres in front of a surface point, on the answering hazcam's
line of sight, so that the hazcam sees the pebble where the point is and the navcams still see the point
(pure numerics, no files). The given scene is not changed (``build_run`` shares its scenes between runs): the
pebbles go into a copy.

The trust model of ``scip`` learns from occluded targets (docs/handoff.md, "Occluded targets in the training
data"). The ones :func:`~scipctl.sim.extra_targets.choose_occluded_targets` finds in a scene are mostly behind
deep occluders (a rock 10 cm to 1.3 m in front), which hazcam stereo catches easily. The hard case is the shallow
one: an occluder a few centimetres in front, whose surroundings look like the target's, and whose stereo range
is close to the target's (``tests/pipeline/test_handoff_broken.py``'s 5 cm disk). Real terrain makes it with a
pebble; this module puts one there.

:func:`add_shallow_occluders` draws surface points the hazcam sees (its rays through uniform pixels), stands a
small faceted rock (:func:`~scipctl.sim.rocks.make_rock`) on the ground in front of each, along the ray's
horizontal direction, and keeps it only if, exactly (ray casts against the pebble and the scene):

* the point is hidden from the hazcam over the whole disk of
  :data:`~scipctl.sim.extra_targets.HIDDEN_DISK_PX` around its pixel, by a surface at least ``min_depth_m`` in
  front of it;
* every image of ``seen_ids`` still sees the point (in the inner part, not occluded), and still sees the points
  that earlier pebbles hide;
* every point of ``protect`` (the run's own targets) is seen by every product exactly as before;
* the pebble stands on the ground, not on a rock.

Site frame (+z down), metres.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .extra_targets import RING_OFFSETS_PX, in_inner_part, inner_pixels, OCCLUDED_KIND
from .marks import project_visible
from .noise import LatticeNoise
from .rocks import ROCK_SHAPES, Rock, make_rock
from .scene import GEOM_ROCKS, Scene, o3d_rays, o3d_triangle_mesh
from .targets import Target

# a pebble: visible length, width/length and height ranges (m), the gap between its far edge and the point (m)
PEBBLE_LENGTH_M = (0.05, 0.10)
PEBBLE_WIDTH_FRAC = (0.6, 0.95)
PEBBLE_HEIGHT_M = (0.03, 0.06)
PEBBLE_GAP_M = (0.0, 0.05)


@dataclass
class ShallowOccluder:
    """A placed pebble and the point it hides: ``target`` (kind ``"occluded"``), ``rock`` (in ``scene.rocks``),
    ``depth_m`` (along the hazcam's centre ray, from the pebble's surface to the point), ``hazcam_uv`` ``(2,)``."""

    target: Target
    rock: Rock
    depth_m: float
    hazcam_uv: np.ndarray


def _first_hit_t(V: np.ndarray, F: np.ndarray, o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """``(N,)`` distance along unit rays ``o + t d`` ``(N, 3)`` to the mesh ``(V, F)`` alone (inf: missed)."""
    from ..core.open3d_import import open3d

    rc = open3d().t.geometry.RaycastingScene()
    rc.add_triangles(o3d_triangle_mesh(V, F))
    return rc.cast_rays(o3d_rays(o, d))["t_hit"].numpy().astype(np.float64)


def _blocked(V, F, origins: np.ndarray, X: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: the segment from ``origins`` ``(N, 3)`` to points ``X`` ``(N, 3)`` meets the mesh before
    the point (by more than 1 mm, the tolerance of :func:`~scipctl.sim.marks.project_visible`)."""
    v = X - origins
    dist = np.linalg.norm(v, axis=1)
    return _first_hit_t(V, F, origins, v / dist[:, None]) < dist - 1e-3


def _visibility(scene: Scene, products: list, X: np.ndarray) -> list:
    """Per product: ``(origins (K, 3), visible (K,))`` of points ``X`` ``(K, 3)``."""
    out = []
    for p in products:
        uv, vis = project_visible(scene, p.model_true_site, p.width, p.height, X)
        o = np.zeros_like(X)
        idx = np.flatnonzero(vis)
        if len(idx):
            o[idx] = p.model_true_site.unproject(uv[idx])[0]
        out.append((o, vis))
    return out


def add_shallow_occluders(scene: Scene, products: list, hazcam_id: str, seen_ids: list, protect: np.ndarray, n: int,
                          rng: np.random.Generator, max_radius_m: float = 1.5, inner_frac: float = 0.06,
                          min_depth_m: float = 0.03, tries: int = 400,
                          id_prefix: str = "p") -> tuple[Scene, list[ShallowOccluder]]:
    """``(scene with pebbles, occluders)``: a copy of ``scene`` with up to ``n`` pebbles appended to its rocks,
    each hiding one surface point from the image ``hazcam_id``; ids ``p01``, ``p02``...

    ``products``: the run's :class:`~scipctl.sim.products.ProductPlan` list; ``seen_ids``: the images that must
    still see each hidden point (the near navcam pair in practice); ``protect`` ``(K, 3)``: site points whose
    visibility in every product must not change (the run's targets). Candidate points are first hits of
    ``hazcam_id``'s rays through ``tries`` uniform pixels of its inner ``1 - 2 inner_frac`` part, within
    ``max_radius_m`` of the target rock's centre; each pebble is drawn from ``rng`` (sizes: the ``PEBBLE_*``
    ranges above). The scene's ray caster is rebuilt after each placement, so later checks see earlier pebbles.
    """
    protect = np.asarray(protect, float).reshape(-1, 3)
    scene = _copy(scene)
    by = {p.product_id: p for p in products}
    hz = by[hazcam_id]
    seen = [by[i] for i in seen_ids]
    uv = inner_pixels(rng, hz.width, hz.height, inner_frac, tries)
    lattice = LatticeNoise(rng, 16)
    out: list[ShallowOccluder] = []
    before = _visibility(scene, products, protect) if len(protect) else []
    seen_rays = [(np.zeros((0, 3)), np.zeros((0, 3))) for _ in seen]  # per seen image: (ray origins, hidden points)
    for uv_c in uv:
        if len(out) >= n:
            break
        o, d = hz.model_true_site.unproject(uv_c[None])
        hit = scene.cast(o, d)
        if not hit.hit[0]:
            continue
        X = hit.points[0]
        if np.hypot(X[0], X[1]) >= max_radius_m:
            continue
        o_seen = []  # per seen image: its ray origin (1, 3) for the point
        for p in seen:
            u, vis = project_visible(scene, p.model_true_site, p.width, p.height, X[None])
            if not (vis[0] and in_inner_part(u, p.width, p.height, inner_frac)[0]):
                break
            o_seen.append(p.model_true_site.unproject(u)[0])
        if len(o_seen) < len(seen):
            continue
        # the pebble: on the ground in front of the point, along the ray's horizontal direction
        L = rng.uniform(*PEBBLE_LENGTH_M)
        size = np.array([L, L * rng.uniform(*PEBBLE_WIDTH_FRAC), rng.uniform(*PEBBLE_HEIGHT_M)])
        dh = d[0, :2] / np.linalg.norm(d[0, :2])
        centre = X[:2] - dh * (0.5 * L + rng.uniform(*PEBBLE_GAP_M))
        down = scene.cast(np.array([[centre[0], centre[1], X[2] - 3.0]]), np.array([[0.0, 0.0, 1.0]]))
        if not down.hit[0] or down.geometry_id[0] == GEOM_ROCKS:
            continue
        rock = make_rock(f"occluder{len(out) + 1:02d}", rng, lattice, scene.field, centre, size, 14, 2, 0.01,
                         rng.uniform(0.7, 1.3), shape=ROCK_SHAPES["faceted"])
        V, F = rock.vertices, rock.triangles
        # hidden over the disk: each ring ray meets the pebble (or the scene) min_depth_m before the point
        uv_ring = uv_c[None] + RING_OFFSETS_PX
        o_r, d_r = hz.model_true_site.unproject(uv_ring)
        t_r = np.minimum(_first_hit_t(V, F, o_r, d_r), scene.cast(o_r, d_r).t_m)
        dist = np.linalg.norm(X[None] - o_r, axis=1)
        if not np.all(t_r <= dist - min_depth_m):
            continue
        # the navcams see over it
        if any(_blocked(V, F, o_k, X[None])[0] for o_k in o_seen):
            continue
        # the run's targets are seen as before
        if any(np.any(_blocked(V, F, o_p[vis], protect[vis])) for o_p, vis in before if vis.any()):
            continue
        # and the navcams still see the points hidden by earlier pebbles
        if out and any(np.any(_blocked(V, F, o_s, X_s)) for o_s, X_s in seen_rays):
            continue
        scene = _copy(scene, rock)
        for k, o_k in enumerate(o_seen):
            seen_rays[k] = (np.concatenate([seen_rays[k][0], o_k]), np.concatenate([seen_rays[k][1], X[None]]))
        depth = float(np.linalg.norm(X - o[0]) - t_r[0])
        tid = f"{id_prefix}{len(out) + 1:02d}"
        out.append(ShallowOccluder(Target(tid, OCCLUDED_KIND, "surface point a pebble hides from the hazcam "
                                          "(trust-model data)", np.asarray(X, float)), rock, depth, uv_c.copy()))
    return scene, out


def _copy(scene: Scene, rock: Rock | None = None) -> Scene:
    """``scene`` with its own rock list (``rock`` appended) and ray caster; the terrain caches are shared."""
    rocks = list(scene.rocks) + ([rock] if rock is not None else [])
    return replace(scene, rocks=rocks, _rc=None, _cache={k: v for k, v in scene._cache.items() if k != "rm"})
