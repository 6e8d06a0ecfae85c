"""Rocks: faceted convex hulls roughened by 3-D noise, standing partly buried on the terrain (pure numerics).

Convex hulls of random points (sharp corners), subdivided and displaced along the normal
by fractal noise, scaled to the wanted extents, yawed and leaned a little, and sunk into
the height field. Vertices are in the site frame (+z down), metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.transforms import axis_angle_to_matrix
from .mesh import hull_mesh, vertex_normals
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


def make_rock(name, rng, lattice, field: HeightField, centre_xy, size_m, n_points, subdiv, rough_frac,
              albedo_scale, is_target=False, sink_frac=0.3) -> Rock:
    """A rock of visible extents ``size_m`` (length, width, height) at ``centre_xy`` on ``field``.

    Hull of ``n_points`` random points, ``subdiv`` midpoint subdivisions, normal displacement of
    ``rough_frac`` x size by fractal noise, random yaw and a small lean; ``sink_frac`` of the total
    height is buried.
    """
    V, F, corners, sharp = hull_mesh(rng, n_points, subdiv)
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
