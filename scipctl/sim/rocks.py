"""Rocks: convex hulls roughened by 3-D noise, standing partly buried on the terrain (pure numerics).

A rock shape (:data:`ROCK_SHAPES`) makes a unit mesh; it is subdivided and displaced along the
normal by fractal noise, scaled to the wanted extents, yawed and leaned a little, and sunk into
the height field. Shapes: ``faceted`` (today's: hulls of random points, sharp corners),
``angular`` (jointed blocks: few large planar faces, straight edges), ``slab`` (tabular: flat top
and bottom, a third as high), ``rounded`` (weathered boulders: smooth, no corners to speak of).
Vertices are in the site frame (+z down), metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.transforms import axis_angle_to_matrix
from .mesh import hull_mesh, hull_of_points, vertex_normals
from .noise import FractalNoise
from .terrain import HeightField


@dataclass
class Rock:
    """A rock in the site frame. ``corner_idx`` indexes ``vertices`` (hull corners; candidates for sharp points)."""

    name: str
    centre_xy_m: np.ndarray  # (2,)
    size_m: np.ndarray  # (3,) full extents: length, width, height above the buried part
    vertices: np.ndarray  # (N, 3) site
    triangles: np.ndarray  # (M, 3)
    corner_idx: np.ndarray
    corner_sharpness_rad: np.ndarray
    albedo_scale: float
    is_target: bool = False

    @property
    def radius_m(self) -> float:
        return float(0.5 * max(self.size_m[0], self.size_m[1]))

    @property
    def top_site(self) -> np.ndarray:
        """Highest vertex (min z) ``(3,)``."""
        return self.vertices[np.argmin(self.vertices[:, 2])].copy()

    def aim_point_site(self) -> np.ndarray:
        """A point to point cameras at: the rock's centre (x, y), halfway up its visible part ``(3,)``."""
        z_top = self.vertices[:, 2].min()
        return np.array([self.centre_xy_m[0], self.centre_xy_m[1], z_top + 0.5 * self.size_m[2]])


# ----------------------------------------------------------------------------- shapes
# unit meshes: (rng, n_points, subdiv) -> (V (N, 3), F (M, 3), corner_idx (K,), corner_sharpness_rad (K,)), around the origin
def faceted_unit_mesh(rng: np.random.Generator, n_points: int, subdiv: int):
    """Hull of ``n_points`` random points at radius 0.72-1 (today's rocks)."""
    return hull_mesh(rng, n_points, subdiv)


def angular_unit_mesh(rng: np.random.Generator, n_points: int, subdiv: int):
    """A jointed block: hull of a sheared, jittered cube's 8 corners and ``n_points // 4`` chips (points well
    inside the corners, cutting them off obliquely) -- few large planar faces, straight edges, no right angles."""
    corners = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
    shear = np.eye(3) + rng.uniform(-0.3, 0.3, size=(3, 3)) * (1 - np.eye(3))
    P = (corners @ shear.T) * rng.uniform(0.75, 1.0, size=(8, 1)) + rng.normal(0.0, 0.15, size=(8, 3))
    k = max(3, n_points // 4)
    pick = rng.integers(0, 8, size=k)
    chips = P[pick] * rng.uniform(0.45, 0.8, size=(k, 1)) + rng.normal(0.0, 0.15, size=(k, 3))
    return hull_of_points(np.concatenate([P, chips]), subdiv)


def slab_unit_mesh(rng: np.random.Generator, n_points: int, subdiv: int):
    """A tabular slab: points of an irregular outline (radius 0.65-1) on a flat top and a flat bottom face."""
    m = max(6, n_points // 2)
    ang = np.sort(rng.uniform(0, 2 * np.pi, size=m))
    rad = rng.uniform(0.65, 1.0, size=m)
    ring = np.stack([rad * np.cos(ang), rad * np.sin(ang)], axis=1)
    top = np.concatenate([ring, np.full((m, 1), 1.0) + rng.normal(0.0, 0.03, size=(m, 1))], axis=1)
    bottom = np.concatenate([ring * rng.uniform(0.85, 1.0, size=(m, 1)), np.full((m, 1), -1.0)], axis=1)
    return hull_of_points(np.concatenate([top, bottom]), subdiv)


def rounded_unit_mesh(rng: np.random.Generator, n_points: int, subdiv: int):
    """A weathered boulder: a fine hull (4 x ``n_points`` directions, one subdivision fewer: as many triangles)
    whose vertices are put on a smooth, lumpy closed surface ``r(d) = 1 + sum_k a_k cos(w_k d.u_k + phi_k)``
    (three low-order lumps)."""
    V, F, corners, sharp = hull_mesh(rng, 4 * n_points, max(subdiv - 1, 0), radius_jitter=(0.97, 1.0))
    u = rng.normal(size=(3, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    a = rng.uniform(0.03, 0.08, size=3)
    w = rng.uniform(1.5, 3.0, size=3)
    phi = rng.uniform(0, 2 * np.pi, size=3)
    d = V / np.linalg.norm(V, axis=1, keepdims=True)
    r = 1.0 + np.cos((d @ u.T) * w + phi) @ a
    return d * r[:, None], F, corners, sharp


@dataclass(frozen=True)
class RockShape:
    """A rock shape: its unit mesh (a sibling function above), the factor on the drawn height (``height_scale``)
    and on the noise roughness (``rough_scale``)."""

    name: str
    unit_mesh: object  # (rng, n_points, subdiv) -> (V, F, corner_idx, sharpness)
    height_scale: float = 1.0
    rough_scale: float = 1.0

    def check(self) -> "RockShape":
        if not (0 < self.height_scale <= 2 and 0 <= self.rough_scale <= 2):
            raise ValueError(f"RockShape {self.name}: height_scale in (0, 2], rough_scale in [0, 2]")
        return self


ROCK_SHAPES = {
    "faceted": RockShape("faceted", faceted_unit_mesh),
    "angular": RockShape("angular", angular_unit_mesh, rough_scale=0.35),
    "slab": RockShape("slab", slab_unit_mesh, height_scale=0.4, rough_scale=0.5),
    "rounded": RockShape("rounded", rounded_unit_mesh, rough_scale=0.5),
}


# ----------------------------------------------------------------------------- rocks
def make_rock(name, rng, lattice, field: HeightField, centre_xy, size_m, n_points, subdiv, rough_frac,
              albedo_scale, is_target=False, sink_frac=0.3, shape: RockShape = ROCK_SHAPES["faceted"]) -> Rock:
    """A rock of visible extents ``size_m`` (length, width, height) at ``centre_xy`` on ``field``.

    ``shape``'s unit mesh from ``n_points`` random points, ``subdiv`` midpoint subdivisions, normal displacement of
    ``rough_frac`` x ``shape.rough_scale`` x size by fractal noise, random yaw and a small lean; ``sink_frac`` of
    the total height is buried (``size_m`` is as given: the caller applies ``shape.height_scale``).
    """
    V, F, corners, sharp = shape.unit_mesh(rng, n_points, subdiv)
    rough_frac = rough_frac * shape.rough_scale
    size_m = np.asarray(size_m, float)
    # unit hull spans about [-1, 1]; scale to the semi-axes (x: length, y: width, z: height incl. buried part)
    lo, hi = V.min(axis=0), V.max(axis=0)
    V = (V - (lo + hi) / 2) / ((hi - lo) / 2)  # exactly [-1, 1]
    total_h = size_m[2] / (1 - sink_frac)
    semi = np.array([size_m[0] / 2, size_m[1] / 2, total_h / 2])
    V = V * semi
    # roughness: displacement along the normal by fractal noise (cm-scale for big rocks)
    nrm = vertex_normals(V, F)
    rough = FractalNoise(lattice, rng, [0.08 * semi.max(), 0.03 * semi.max(), 0.012 * semi.max()], [1.0, 0.6, 0.35])
    V = V + (rough_frac * semi.max() * 2.0 * rough(V))[:, None] * nrm
    # V: x forward, y right, z UP (local). yaw about the vertical and a little lean
    yaw = rng.uniform(0, 2 * np.pi)
    lean = rng.normal(0, 0.06, size=2)
    Rl = axis_angle_to_matrix([0, 0, 1], yaw) @ axis_angle_to_matrix([1, 0, 0], lean[0]) @ axis_angle_to_matrix([0, 1, 0], lean[1])
    V = V @ Rl.T
    V[:, 2] -= V[:, 2].min()  # bottom at 0 (local up)
    cxy = np.asarray(centre_xy, float)
    g = field.height_m(cxy[None])[0]
    up = V[:, 2] - sink_frac * total_h  # bottom buried by sink_frac of the total height
    site = np.empty_like(V)
    site[:, 0] = V[:, 0] + cxy[0]
    site[:, 1] = V[:, 1] + cxy[1]
    site[:, 2] = -(g + up)
    # actual visible extents
    vis_h = float(up.max())
    ext = np.array([np.ptp(V[:, 0]), np.ptp(V[:, 1]), vis_h])
    return Rock(name, cxy, ext, site, F.astype(np.int64), corners, sharp, float(albedo_scale), is_target)
