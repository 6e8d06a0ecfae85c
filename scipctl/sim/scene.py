"""Synthetic Mars-like scenes with exact geometry (pure numerics; Open3D for ray casting).

Site frame: +x north, +y east, +z **down** (heights above the ground are
negative z). The scene's big target rock sits at the site origin (x, y) =
(0, 0); the terrain extends to +-150 m.

Content, all reproducible from ``make_scene(seed)``:

* terrain: a triangulated height field ``z = -h(x, y)``, ``h`` a sum of
  sinusoids with random directions (wavelengths 0.2 - 60 m, amplitude about
  0.4 % of the wavelength: rolling ground, cm-scale bumps). The grid is 2 cm
  within 4 m of the target rock and grows geometrically outside (no cracks:
  one tensor-product grid); wavelengths the local grid cannot carry are faded
  out there.
* rocks: convex hulls of random points (faceted, with sharp corners),
  subdivided and roughened by 3-D noise, scaled to 0.2 - 0.6 m, partly buried;
  one large target rock (~0.55 x 0.45 x 0.3 m) at the origin; other rocks are
  kept out of ``keep_clear`` corridors (the rover's approach paths).
* pebbles: small hulls (1 - 6 cm), dense near the target rock, sparse outside;
  none inside a few drift-sand patches near the rock.
* appearance: Lambertian albedo that is a procedural function of the 3-D
  surface point (multi-octave 3-D value noise with per-material statistics and
  high-contrast spots), so it is the same from every viewpoint; the sun
  direction and an ambient term are part of the scene.

Arrays: points ``(N, 3)`` site frame metres; ``xy`` ``(N, 2)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..core.transforms import axis_angle_to_matrix
from .noise import FractalNoise, LatticeNoise, lod_weight

MAT_SKY, MAT_TERRAIN, MAT_ROCK, MAT_PEBBLE = -1, 0, 1, 2
GEOM_TERRAIN, GEOM_ROCKS, GEOM_PEBBLES = 0, 1, 2

INNER_HALF_M = 4.0
INNER_STEP_M = 0.02
OUTER_HALF_M = 150.0
GROWTH = 1.07
MAX_STEP_M = 4.0


# ----------------------------------------------------------------------------- terrain
@dataclass(frozen=True)
class HeightField:
    """``h(x, y) = sum_k a_k sin(k_k . (x, y) + phi_k)`` metres above the datum (site z = -h)."""

    wavevectors: np.ndarray  # (K, 2) rad/m
    amplitudes_m: np.ndarray  # (K,)
    phases_rad: np.ndarray  # (K,)

    @property
    def wavelengths_m(self) -> np.ndarray:
        return 2 * np.pi / np.linalg.norm(self.wavevectors, axis=1)

    def _fade(self, spacing_m):
        if spacing_m is None:
            return 1.0
        # a wave needs >= 8 grid steps per wavelength to be carried; fade between 8 and 16
        r = self.wavelengths_m[None, :] / np.maximum(np.asarray(spacing_m, float)[:, None], 1e-9)
        return np.clip((r - 8.0) / 8.0, 0.0, 1.0)

    def height_and_gradient(self, xy, spacing_m=None, chunk: int = 32768):
        """``xy`` ``(N, 2)`` -> heights ``(N,)`` (positive up) and gradients ``(N, 2)`` (dh/dx, dh/dy).

        ``spacing_m`` ``(N,)``: fade out waves too short for a grid of that spacing (as the mesh is built).
        """
        xy = np.asarray(xy, float)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"xy: expected shape (N, 2), got {xy.shape}")
        N = len(xy)
        h = np.zeros(N)
        g = np.zeros((N, 2))
        if spacing_m is None:
            groups = [(np.arange(N), np.arange(len(self.amplitudes_m)))]
        else:
            sp = np.broadcast_to(np.asarray(spacing_m, float), (N,))
            # waves a vertex can carry at all (fade > 0): wavelength > 8 x spacing; group vertices by that set
            need = np.searchsorted(np.sort(-self.wavelengths_m), -8.0 * sp, side="left")  # count of long-enough waves
            order = np.argsort(-self.wavelengths_m, kind="stable")
            groups = [(np.nonzero(need == k)[0], order[:k]) for k in np.unique(need) if k > 0]
        for vid, wid in groups:
            K = self.wavevectors[wid]
            for i in range(0, len(vid), chunk):
                sel = vid[i:i + chunk]
                ph = xy[sel] @ K.T
                ph += self.phases_rad[wid][None, :]
                w = self.amplitudes_m[wid][None, :]
                if spacing_m is not None:
                    r = self.wavelengths_m[wid][None, :] / np.maximum(sp[sel][:, None], 1e-9)
                    w = w * np.clip((r - 8.0) / 8.0, 0.0, 1.0)
                h[sel] = np.einsum("ij,ij->i", np.sin(ph), w)
                g[sel] = (np.cos(ph) * w) @ K
        return h, g

    def height_m(self, xy, spacing_m=None) -> np.ndarray:
        """``xy`` ``(N, 2)`` -> ``(N,)`` heights (positive up)."""
        return self.height_and_gradient(xy, spacing_m)[0]

    def gradient(self, xy, spacing_m=None) -> np.ndarray:
        """``(N, 2)`` = (dh/dx, dh/dy)."""
        return self.height_and_gradient(xy, spacing_m)[1]

    def normal_site(self, xy, spacing_m=None) -> np.ndarray:
        """Upward unit normal ``(N, 3)`` in the site frame (z down): ``(-hx, -hy, -1)/norm``."""
        g = self.gradient(xy, spacing_m)
        n = np.concatenate([-g, -np.ones((g.shape[0], 1))], axis=1)
        return n / np.linalg.norm(n, axis=1, keepdims=True)


def random_height_field(rng: np.random.Generator, n_waves: int = 48, roughness: float = 0.004) -> HeightField:
    lam = np.exp(rng.uniform(np.log(0.2), np.log(60.0), size=n_waves))
    lam.sort()
    ang = rng.uniform(0, 2 * np.pi, size=n_waves)
    k = (2 * np.pi / lam)[:, None] * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    amp = roughness * lam * rng.uniform(0.4, 1.0, size=n_waves)
    phase = rng.uniform(0, 2 * np.pi, size=n_waves)
    return HeightField(k, amp, phase)


def graded_axis(inner_half_m=INNER_HALF_M, inner_step_m=INNER_STEP_M, outer_half_m=OUTER_HALF_M,
                growth=GROWTH, max_step_m=MAX_STEP_M) -> np.ndarray:
    """Grid line positions ``(K,)``: uniform in ``[-inner, inner]``, geometric growth outside, to ``+-outer``."""
    n_in = int(round(inner_half_m / inner_step_m))
    inner = np.arange(-n_in, n_in + 1) * inner_step_m
    outer = []
    x, step = inner_half_m, inner_step_m
    while x < outer_half_m:
        step = min(step * growth, max_step_m)
        x = min(x + step, outer_half_m)
        outer.append(x)
    outer = np.array(outer)
    return np.concatenate([-outer[::-1], inner, outer])


def grid_mesh(xs: np.ndarray, ys: np.ndarray):
    """Tensor grid -> (vertex xy ``(nx*ny, 2)``, triangles ``(2(nx-1)(ny-1), 3)``, local spacing ``(nx*ny,)``)."""
    nx, ny = len(xs), len(ys)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    xy = np.stack([X.ravel(), Y.ravel()], axis=1)
    dx = np.maximum(np.diff(xs, prepend=xs[0] - (xs[1] - xs[0])), np.diff(xs, append=xs[-1] + (xs[-1] - xs[-2])))
    dy = np.maximum(np.diff(ys, prepend=ys[0] - (ys[1] - ys[0])), np.diff(ys, append=ys[-1] + (ys[-1] - ys[-2])))
    spacing = np.maximum(dx[:, None], dy[None, :]).ravel()
    idx = np.arange(nx * ny).reshape(nx, ny)
    a = idx[:-1, :-1].ravel()
    b = idx[1:, :-1].ravel()
    c = idx[1:, 1:].ravel()
    d = idx[:-1, 1:].ravel()
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return xy, tris, spacing


# ----------------------------------------------------------------------------- rocks
def _subdivide(V: np.ndarray, F: np.ndarray):
    """One midpoint subdivision: each triangle -> 4. Returns (V', F')."""
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    e = np.sort(e, axis=1)
    uniq, inv = np.unique(e, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    mids = 0.5 * (V[uniq[:, 0]] + V[uniq[:, 1]])
    base = len(V)
    nF = len(F)
    m01 = base + inv[:nF]
    m12 = base + inv[nF:2 * nF]
    m20 = base + inv[2 * nF:]
    a, b, c = F[:, 0], F[:, 1], F[:, 2]
    F2 = np.concatenate([
        np.stack([a, m01, m20], 1), np.stack([m01, b, m12], 1), np.stack([m20, m12, c], 1), np.stack([m01, m12, m20], 1),
    ])
    return np.concatenate([V, mids]), F2


def vertex_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals ``(N, 3)`` of a consistently oriented mesh."""
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    vn = np.zeros_like(V)
    for k in range(3):
        np.add.at(vn, F[:, k], fn)
    n = np.linalg.norm(vn, axis=1, keepdims=True)
    return vn / np.maximum(n, 1e-30)


def hull_mesh(rng: np.random.Generator, n_points: int, subdiv: int, radius_jitter=(0.72, 1.0)):
    """A faceted unit-scale rock: convex hull of random points, outward-oriented, subdivided.

    Returns ``(V (N, 3), F (M, 3), corner_idx (K,), corner_sharpness (K,))``; corners are the hull
    vertices, ``sharpness`` = angle deficit (rad; high = pointed).
    """
    from scipy.spatial import ConvexHull

    d = rng.normal(size=(n_points, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    P = d * rng.uniform(*radius_jitter, size=(n_points, 1))
    hull = ConvexHull(P)
    used = np.unique(hull.simplices)
    remap = -np.ones(n_points, int)
    remap[used] = np.arange(len(used))
    V = P[used]
    F = remap[hull.simplices]
    ctr = V.mean(axis=0)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    flip = np.sum(fn * (V[F].mean(axis=1) - ctr), axis=1) < 0
    F[flip] = F[flip][:, ::-1]
    # angle deficit at the hull vertices
    ang_sum = np.zeros(len(V))
    for k in range(3):
        a = V[F[:, k]]
        b = V[F[:, (k + 1) % 3]] - a
        c = V[F[:, (k + 2) % 3]] - a
        cosang = np.sum(b * c, 1) / (np.linalg.norm(b, axis=1) * np.linalg.norm(c, axis=1))
        np.add.at(ang_sum, F[:, k], np.arccos(np.clip(cosang, -1, 1)))
    sharp = 2 * np.pi - ang_sum
    n_corner = len(V)
    for _ in range(subdiv):
        V, F = _subdivide(V, F)
    return V, F, np.arange(n_corner), sharp


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


# ----------------------------------------------------------------------------- appearance
@dataclass
class Appearance:
    """Procedural albedo: per-material fractal noise + spots. Call :meth:`albedo`."""

    soil: FractalNoise
    sand: FractalNoise
    rock: FractalNoise
    spots: FractalNoise  # high-contrast specks (thresholded)
    rock_spots: FractalNoise
    patches: FractalNoise  # metre-scale albedo variation of the ground
    sand_patches: np.ndarray  # (K, 3) x, y, radius_m of drift-sand patches
    soil_albedo: float = 0.34
    sand_albedo: float = 0.44
    rock_albedo: float = 0.26
    texture: Optional[object] = None  # a sim.texture.SurfaceTexture: real relative albedo replacing the soil's grain

    def sand_weight(self, xy: np.ndarray) -> np.ndarray:
        """0 (soil) .. 1 (drift sand) ``(N,)``: irregular patches (radius modulated by the angle) with a soft 4 cm edge."""
        w = np.zeros(len(xy), np.float32)
        for x, y, r in self.sand_patches:
            near = np.flatnonzero((np.abs(xy[:, 0] - x) < 1.4 * r) & (np.abs(xy[:, 1] - y) < 1.4 * r))
            if len(near) == 0:
                continue
            dx, dy = xy[near, 0] - x, xy[near, 1] - y
            d = np.hypot(dx, dy)
            a = np.arctan2(dy, dx)
            k = 1000.0 * r  # fixed per patch: a deterministic wobble
            rr = r * (1 + 0.12 * np.sin(3 * a + k) + 0.07 * np.sin(5 * a + 2 * k) + 0.04 * np.sin(11 * a + 3 * k))
            w[near] = np.maximum(w[near], np.clip((rr - d) / 0.04, 0, 1).astype(np.float32))
        return w

    def albedo(self, P: np.ndarray, material: np.ndarray, obj_scale: np.ndarray, footprint_m: Optional[np.ndarray]) -> np.ndarray:
        """Albedo ``(N,)`` float32 of surface points ``P`` ``(N, 3)`` site; ``material`` ``(N,)``; ``obj_scale`` ``(N,)``.

        ``footprint_m`` ``(N,)`` (pixel footprint on the surface) fades octaves finer than a pixel; None = full detail.
        """
        N = P.shape[0]
        out = np.zeros(N, np.float32)
        f32 = np.float32

        def sub(a, idx):
            return None if a is None else a[idx]

        ter = np.flatnonzero(material == MAT_TERRAIN)
        if len(ter):
            PT = np.ascontiguousarray(P[ter].T, np.float32)
            f = sub(footprint_m, ter)
            ws = self.sand_weight(P[ter, :2])
            base = (1 - ws) * f32(self.soil_albedo) + ws * f32(self.sand_albedo)
            base *= f32(1.0) + self.patches.eval_T(PT, f)
            soil = np.flatnonzero(ws < 1)
            tex = np.zeros(len(ter), np.float32)
            if self.texture is not None:  # real texture: a function of the ground point (x, y), faded by the footprint
                if len(soil):
                    tex[soil] = self.texture.sample(PT[:2, soil].T, sub(f, soil))
            elif len(soil) == len(ter):
                tex = self.soil.eval_T(PT, f)
            elif len(soil):
                tex[soil] = self.soil.eval_T(np.ascontiguousarray(PT[:, soil]), sub(f, soil))
            sel = np.flatnonzero(ws > 0)
            if len(sel):
                sand = self.sand.eval_T(np.ascontiguousarray(PT[:, sel]), sub(f, sel))
                # wind ripples: ~9 cm crests across the prevailing wind, a little wavy (faded below the footprint)
                x, y = PT[0, sel], PT[1, sel]
                ph = f32(2 * np.pi / 0.09) * (f32(0.8) * x + f32(0.6) * y) + f32(1.5) * np.sin(f32(2 * np.pi / 0.7) * (f32(-0.6) * x + f32(0.8) * y))
                rip = f32(0.07) * np.sin(ph)
                if f is not None:
                    rip *= lod_weight(0.09 / 4, f[sel])
                tex[sel] = (1 - ws[sel]) * tex[sel] + ws[sel] * (sand + rip)
            a = base * (f32(1.0) + tex)
            if self.texture is None:  # the real texture carries its own specks
                s = self.spots.eval_T(PT, f)  # ~[-0.5, 0.5]
                dark = np.clip((s - f32(0.3)) / f32(0.06), 0, 1) * (1 - ws)
                bright = np.clip((-s - f32(0.32)) / f32(0.06), 0, 1) * (1 - ws)
                a = a * (1 - f32(0.65) * dark) + f32(0.35) * bright
            out[ter] = a
        rk = np.flatnonzero((material == MAT_ROCK) | (material == MAT_PEBBLE))
        if len(rk):
            PT = np.ascontiguousarray(P[rk].T, np.float32)
            f = sub(footprint_m, rk)
            a = f32(self.rock_albedo) * obj_scale[rk].astype(np.float32) * (f32(1.0) + self.rock.eval_T(PT, f))
            s = self.rock_spots.eval_T(PT, f)
            bright = np.clip((s - f32(0.19)) / f32(0.05), 0, 1)
            dark = np.clip((-s - f32(0.21)) / f32(0.05), 0, 1)
            a = a * (1 - f32(0.6) * dark) + f32(0.4) * bright
            out[rk] = a
        return np.clip(out, 0.02, 0.98).astype(np.float32)


def make_appearance(rng: np.random.Generator, sand_patches: np.ndarray) -> Appearance:
    lattice = LatticeNoise(rng, 128)
    soil = FractalNoise(lattice, rng, [0.0025, 0.005, 0.01, 0.02, 0.04, 0.09], [0.3, 0.32, 0.3, 0.25, 0.22, 0.18])
    sand = FractalNoise(lattice, rng, [0.002, 0.004, 0.008, 0.02, 0.06], [0.22, 0.18, 0.14, 0.12, 0.12])
    rock = FractalNoise(lattice, rng, [0.003, 0.006, 0.012, 0.025, 0.05, 0.1], [0.35, 0.4, 0.45, 0.5, 0.45, 0.3])
    spots = FractalNoise(lattice, rng, [0.006, 0.012], [1.0, 0.5])
    rock_spots = FractalNoise(lattice, rng, [0.005, 0.01, 0.02], [0.7, 0.6, 0.4])
    patches = FractalNoise(lattice, rng, [0.3, 1.2, 5.0], [0.25, 0.3, 0.3])
    return Appearance(soil, sand, rock, spots, rock_spots, patches, sand_patches)


# ----------------------------------------------------------------------------- scene
def _rowdot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise dot products of ``(N, 3)`` arrays -> ``(N,)`` (no BLAS: cheap and thread-friendly)."""
    return np.einsum("ij,ij->i", a, b)


@dataclass
class Hits:
    """Result of :meth:`Scene.cast` for ``N`` rays (site frame)."""

    t_m: np.ndarray  # (N,) float64, inf where nothing was hit
    hit: np.ndarray  # (N,) bool
    points: np.ndarray  # (N, 3) float64 (NaN where no hit)
    normal: np.ndarray  # (N, 3) shading normal, facing the ray origin
    normal_geom: np.ndarray  # (N, 3) triangle normal, facing the ray origin
    material: np.ndarray  # (N,) int8: MAT_*
    obj_scale: np.ndarray  # (N,) float32 per-object albedo factor
    geometry_id: np.ndarray  # (N,) int64 (-1: no hit)
    primitive_id: np.ndarray  # (N,) int64


@dataclass
class Scene:
    seed: int
    field: HeightField
    terrain_axis_m: np.ndarray  # (n,) grid line positions, the same for x and y
    terrain_xy: np.ndarray  # (Nv, 2) = all (x_i, y_j), index i * n + j
    terrain_tris: np.ndarray  # (Mt, 3)
    terrain_spacing_m: np.ndarray  # (Nv,)
    rocks: list  # list[Rock]; rocks[0] is the target rock
    pebble_vertices: np.ndarray  # (Np, 3)
    pebble_tris: np.ndarray  # (Mp, 3)
    pebble_tri_scale: np.ndarray  # (Mp,) albedo factor per triangle
    appearance: Appearance
    sun_dir_site: np.ndarray  # (3,) unit vector towards the sun (z down: sun up has z < 0)
    ambient: float = 0.28
    sky_radiance: float = 0.42
    _rc: object = field(default=None, repr=False)
    _cache: dict = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------ geometry
    @property
    def target_rock(self) -> Rock:
        return self.rocks[0]

    def terrain_vertices(self) -> np.ndarray:
        if "tv" not in self._cache:
            h, g = self.field.height_and_gradient(self.terrain_xy, self.terrain_spacing_m)
            self._cache["tv"] = np.concatenate([self.terrain_xy, -h[:, None]], axis=1)
            n = np.concatenate([-g, -np.ones((len(g), 1))], axis=1)
            self._cache["tn"] = n / np.linalg.norm(n, axis=1, keepdims=True)
        return self._cache["tv"]

    def terrain_normals(self) -> np.ndarray:
        self.terrain_vertices()
        return self._cache["tn"]

    def rock_mesh(self):
        """All rocks merged: ``(V, F, per-triangle albedo scale)``."""
        if "rm" not in self._cache:
            Vs, Fs, Ss, off = [], [], [], 0
            for r in self.rocks:
                Vs.append(r.vertices)
                Fs.append(r.triangles + off)
                Ss.append(np.full(len(r.triangles), r.albedo_scale, np.float32))
                off += len(r.vertices)
            self._cache["rm"] = (np.concatenate(Vs), np.concatenate(Fs), np.concatenate(Ss))
        return self._cache["rm"]

    @property
    def n_triangles(self) -> int:
        return len(self.terrain_tris) + len(self.rock_mesh()[1]) + len(self.pebble_tris)

    def _mesh(self, V, F):
        import open3d as o3d

        m = o3d.t.geometry.TriangleMesh()
        m.vertex.positions = o3d.core.Tensor(np.ascontiguousarray(V, np.float32))
        m.triangle.indices = o3d.core.Tensor(np.ascontiguousarray(F, np.uint32))
        return m

    def raycaster(self):
        """The Open3D ``RaycastingScene`` (built once): terrain, rocks, pebbles."""
        if self._rc is None:
            import open3d as o3d

            rc = o3d.t.geometry.RaycastingScene()
            ids = [
                rc.add_triangles(self._mesh(self.terrain_vertices(), self.terrain_tris)),
                rc.add_triangles(self._mesh(*self.rock_mesh()[:2])),
            ]
            if len(self.pebble_tris):
                ids.append(rc.add_triangles(self._mesh(self.pebble_vertices, self.pebble_tris)))
            if ids != list(range(len(ids))):
                raise RuntimeError(f"unexpected Open3D geometry ids {ids}")
            self._rc = rc
        return self._rc

    @staticmethod
    def _rays(origins, dirs):
        import open3d as o3d

        r = np.empty((len(origins), 6), np.float32)
        r[:, :3] = origins
        r[:, 3:] = dirs
        return o3d.core.Tensor(r)

    def _cast_raw(self, rc, origins, dirs):
        return rc.cast_rays(self._rays(origins, dirs))

    def cast(self, origins, dirs) -> Hits:
        """First hits of rays ``origins`` ``(N, 3)`` + t ``dirs`` ``(N, 3)`` (unit) in the site frame."""
        origins = np.asarray(origins, float)
        dirs = np.asarray(dirs, float)
        if origins.shape != dirs.shape or origins.ndim != 2 or origins.shape[1] != 3:
            raise ValueError(f"origins/dirs: expected equal shapes (N, 3), got {origins.shape} {dirs.shape}")
        ans = self._cast_raw(self.raycaster(), origins, dirs)
        t = ans["t_hit"].numpy().astype(np.float64)
        hit = np.isfinite(t)
        gid = ans["geometry_ids"].numpy().astype(np.int64)
        pid = ans["primitive_ids"].numpy().astype(np.int64)
        gid[~hit] = -1
        pid[~hit] = -1
        uvb = ans["primitive_uvs"].numpy()
        ng = ans["primitive_normals"].numpy().astype(np.float64)
        N = len(t)
        if hit.all():
            P = dirs * t[:, None]
            P += origins
        else:
            P = np.full((N, 3), np.nan)
            hi = np.flatnonzero(hit)
            P[hi] = origins[hi] + t[hi, None] * dirs[hi]
        mat = np.full(N, MAT_SKY, np.int8)
        scale = np.ones(N, np.float32)
        nsh = ng.copy()
        ter = np.flatnonzero(gid == GEOM_TERRAIN)
        if len(ter):
            mat[ter] = MAT_TERRAIN
            tri = self.terrain_tris[pid[ter]]
            vn = self.terrain_normals()
            u = uvb[ter, 0:1].astype(np.float64)
            v = uvb[ter, 1:2].astype(np.float64)
            n = vn[tri[:, 0]]
            n *= 1 - u - v
            n += u * vn[tri[:, 1]]
            n += v * vn[tri[:, 2]]
            n /= np.sqrt(_rowdot(n, n))[:, None]
            nsh[ter] = n
        rk = np.flatnonzero(gid == GEOM_ROCKS)
        if len(rk):
            mat[rk] = MAT_ROCK
            scale[rk] = self.rock_mesh()[2][pid[rk]]
        pb = np.flatnonzero(gid == GEOM_PEBBLES)
        if len(pb):
            mat[pb] = MAT_PEBBLE
            scale[pb] = self.pebble_tri_scale[pid[pb]]
        # face the viewer
        flip = _rowdot(ng, dirs) > 0
        ng[flip] *= -1.0
        flip2 = _rowdot(nsh, ng) < 0
        nsh[flip2] *= -1.0
        return Hits(np.where(hit, t, np.inf), hit, P, nsh, ng, mat, scale, gid, pid)

    def occluded(self, origins, dirs, t_max) -> np.ndarray:
        """``(N,)`` bool: something is hit along ``origins + t dirs`` for ``0 < t < t_max`` ``(N,)``."""
        origins = np.asarray(origins, float)
        dirs = np.asarray(dirs, float)
        rays = self._rays(origins, np.broadcast_to(dirs, origins.shape))
        tmax = np.broadcast_to(np.asarray(t_max, float), (len(origins),))
        # test_occlusions takes one tfar; group by +inf vs finite via cast_rays when finite
        if np.all(np.isinf(tmax)):
            return self.raycaster().test_occlusions(rays).numpy().astype(bool)
        t = self.raycaster().cast_rays(rays)["t_hit"].numpy().astype(np.float64)
        return t < tmax

    def ground_height_m(self, xy) -> np.ndarray:
        """Height (positive up) of the terrain mesh under ``xy`` ``(N, 2)`` (rocks and pebbles ignored).

        Exact for the triangulated grid: the cell is looked up and its triangle interpolated.
        """
        xy = np.asarray(xy, float).reshape(-1, 2)
        ax = self.terrain_axis_m
        n = len(ax)
        if np.any(np.abs(xy) > ax[-1]):
            raise ValueError("ground_height_m: point outside the terrain")
        i = np.clip(np.searchsorted(ax, xy[:, 0], side="right") - 1, 0, n - 2)
        j = np.clip(np.searchsorted(ax, xy[:, 1], side="right") - 1, 0, n - 2)
        fx = (xy[:, 0] - ax[i]) / (ax[i + 1] - ax[i])
        fy = (xy[:, 1] - ax[j]) / (ax[j + 1] - ax[j])
        h = -self.terrain_vertices()[:, 2]
        ha, hb, hc, hd = h[i * n + j], h[(i + 1) * n + j], h[(i + 1) * n + j + 1], h[i * n + j + 1]
        lower = fx >= fy  # triangle (a, b, c); else (a, c, d)
        return np.where(lower, ha + fx * (hb - ha) + fy * (hc - hb), ha + fy * (hd - ha) + fx * (hc - hd))

    # ----------------------------------------------------------- appearance
    def radiance(self, hits: Hits, dirs: np.ndarray, footprint_m: Optional[np.ndarray] = None, shadows: bool = True) -> np.ndarray:
        """Radiance ``(N,)`` float32 (albedo x irradiance; sky where nothing was hit)."""
        N = len(hits.t_m)
        out = np.empty(N, np.float32)
        sky = ~hits.hit
        if np.any(sky):
            el = np.clip(-dirs[sky, 2], 0, 1)  # sine of the elevation (z down)
            out[sky] = np.float32(self.sky_radiance) * (np.float32(1.15) - np.float32(0.35) * el.astype(np.float32))
        idx = np.nonzero(hits.hit)[0]
        if len(idx) == 0:
            return out
        P = hits.points[idx]
        n = hits.normal[idx]
        ng = hits.normal_geom[idx]
        s = self.sun_dir_site
        cos_s = np.clip(n[:, 0] * s[0] + n[:, 1] * s[1] + n[:, 2] * s[2], 0, None)
        cos_g = ng[:, 0] * s[0] + ng[:, 1] * s[1] + ng[:, 2] * s[2]
        lit = (cos_s > 0) & (cos_g > 0)
        if shadows and np.any(lit):
            li = np.flatnonzero(lit)
            o = P[li] + 2e-4 * ng[li]
            occ = self.occluded(o, s, np.inf)
            lit[li[occ]] = False
        # irradiance: ambient + direct sun, normalised so that level ground in full sun gets 1
        sun_norm = np.float32(1 - self.ambient) / np.float32(max(-s[2], 0.3))
        irr = np.float32(self.ambient) + sun_norm * np.where(lit, cos_s, 0).astype(np.float32)
        alb = self.appearance.albedo(P, hits.material[idx], hits.obj_scale[idx], None if footprint_m is None else footprint_m[idx])
        out[idx] = alb * irr
        return out


# ----------------------------------------------------------------------------- construction
def _dist_to_segments(xy, segments):
    """Distance ``(N,)`` from points ``(N, 2)`` to the nearest of segments ``[(p0 (2,), p1 (2,), half_width)]``, minus its half width."""
    out = np.full(len(xy), np.inf)
    for p0, p1, hw in segments:
        p0 = np.asarray(p0, float)
        p1 = np.asarray(p1, float)
        d = p1 - p0
        L2 = max(float(d @ d), 1e-12)
        t = np.clip(((xy - p0) @ d) / L2, 0, 1)
        q = p0 + t[:, None] * d
        out = np.minimum(out, np.linalg.norm(xy - q, axis=1) - hw)
    return out


def make_scene(seed: int, keep_clear=(), n_near_rocks: int = 5, sun_elevation_deg: Optional[float] = None,
               sun_azimuth_rad: Optional[float] = None, texture=None) -> Scene:
    """A scene from ``seed`` (any int). ``keep_clear``: ``[(p0_xy, p1_xy, half_width_m), ...]`` corridors free of rocks.

    The target rock is ``scene.rocks[0]`` at the origin. ``sun_azimuth_rad``: direction (from north towards
    east) in which the sun stands; default random. ``texture``: a :class:`~scipctl.sim.texture.SurfaceTexture`
    whose relative albedo replaces the procedural soil grain and specks (geometry and random draws unchanged).
    """
    ss = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, 0x5C1B])
    r_field, r_rock, r_peb, r_app, r_sun = (np.random.default_rng(s) for s in ss.spawn(5))
    field_ = random_height_field(r_field)
    xs = graded_axis()
    xy, tris, spacing = grid_mesh(xs, xs)
    lattice = LatticeNoise(r_rock, 48)

    rocks = []
    tsize = np.array([r_rock.uniform(0.52, 0.6), r_rock.uniform(0.42, 0.5), r_rock.uniform(0.28, 0.34)])
    rocks.append(make_rock("rock00", r_rock, lattice, field_, (0.0, 0.0), tsize, 34, 5, 0.012, r_rock.uniform(0.9, 1.15), True, 0.25))
    # other rocks: a few near the target, more scattered further out, none in the corridors
    placed = [(np.zeros(2), rocks[0].radius_m)]

    def try_place(rmin, rmax, size_lo, size_hi, subdiv, tries=60):
        for _ in range(tries):
            rad = np.sqrt(r_rock.uniform(rmin ** 2, rmax ** 2))
            ang = r_rock.uniform(0, 2 * np.pi)
            c = np.array([rad * np.cos(ang), rad * np.sin(ang)])
            L = r_rock.uniform(size_lo, size_hi)
            sz = np.array([L, L * r_rock.uniform(0.6, 0.95), L * r_rock.uniform(0.35, 0.6)])
            rr = 0.5 * sz[0]
            if keep_clear and _dist_to_segments(c[None], keep_clear)[0] < rr + 0.15:
                continue
            if any(np.linalg.norm(c - pc) < rr + pr + 0.25 for pc, pr in placed):
                continue
            placed.append((c, rr))
            return c, sz, subdiv
        return None

    specs = []
    for _ in range(n_near_rocks):
        s = try_place(1.0, 4.0, 0.2, 0.45, 4)
        if s:
            specs.append(s)
    for _ in range(40):
        s = try_place(4.0, 25.0, 0.2, 0.6, 3)
        if s:
            specs.append(s)
    for k, (c, sz, sd) in enumerate(specs, start=1):
        rocks.append(make_rock(f"rock{k:02d}", r_rock, lattice, field_, c, sz, int(r_rock.integers(16, 30)), sd, 0.015,
                               r_rock.uniform(0.75, 1.25)))

    # drift-sand patches near the target rock (pebble-free)
    sand = []
    for _ in range(12):
        if len(sand) >= 3:
            break
        rad = r_peb.uniform(0.8, 2.2)
        ang = r_peb.uniform(0, 2 * np.pi)
        c = np.array([rad * np.cos(ang), rad * np.sin(ang)])
        R = r_peb.uniform(0.3, 0.55)
        if any(np.linalg.norm(c - pc) < R + pr + 0.05 for pc, pr in placed):
            continue
        sand.append((c[0], c[1], R))
    sand = np.array(sand, float).reshape(-1, 3)

    # pebbles: instances of a few dozen prototype hulls, randomly rotated and scaled, partly buried
    protos = [hull_mesh(r_peb, int(r_peb.integers(9, 14)), 1)[:2] for _ in range(40)]
    protos += [hull_mesh(r_peb, int(r_peb.integers(10, 16)), 2)[:2] for _ in range(12)]
    for k, (V, F) in enumerate(protos):
        lo, hi = V.min(axis=0), V.max(axis=0)
        protos[k] = ((V - (lo + hi) / 2) / ((hi - lo) / 2), F)
    pc = np.array([c for c, _ in placed])
    pr = np.array([r for _, r in placed])

    def zone(n, rmin, rmax, size_lo, size_hi, proto_lo, proto_hi):
        rad = np.sqrt(r_peb.uniform(rmin ** 2, rmax ** 2, size=n))
        ang = r_peb.uniform(0, 2 * np.pi, size=n)
        cs = np.stack([rad * np.cos(ang), rad * np.sin(ang)], 1)
        L = np.exp(r_peb.uniform(np.log(size_lo), np.log(size_hi), size=n))
        sz = np.stack([L, L * r_peb.uniform(0.6, 1.0, n), L * r_peb.uniform(0.4, 0.7, n)], 1)
        yaw = r_peb.uniform(0, 2 * np.pi, n)
        proto = r_peb.integers(proto_lo, proto_hi, n)
        alb = r_peb.uniform(0.6, 1.6, n)
        ok = np.all(np.linalg.norm(cs[:, None, :] - pc[None], axis=2) > pr[None] + 0.5 * L[:, None], axis=1)
        if len(sand):
            ok &= np.all(np.hypot(cs[:, None, 0] - sand[None, :, 0], cs[:, None, 1] - sand[None, :, 1])
                         > sand[None, :, 2] + 0.5 * L[:, None], axis=1)
        return [(cs[i], sz[i], yaw[i], proto[i], alb[i]) for i in np.nonzero(ok)[0]]

    items = zone(1100, 0.35, 4.0, 0.01, 0.03, 0, 40) + zone(160, 0.35, 4.0, 0.03, 0.07, 40, 52) \
        + zone(900, 4.0, 16.0, 0.02, 0.08, 0, 40)
    ground = field_.height_m(np.array([it[0] for it in items]).reshape(-1, 2))
    Vp, Fp, Sp, off = [], [], [], 0
    for (c, sz, yaw, k, alb), g in zip(items, ground):
        V, F = protos[k]
        sink = 0.35 * sz[2]
        Vl = V * (sz / 2)
        cy, sy = np.cos(yaw), np.sin(yaw)
        x = cy * Vl[:, 0] - sy * Vl[:, 1] + c[0]
        y = sy * Vl[:, 0] + cy * Vl[:, 1] + c[1]
        up = Vl[:, 2] + sz[2] / 2 - sink
        Vp.append(np.stack([x, y, -(g + up)], 1))
        Fp.append(F + off)
        Sp.append(np.full(len(F), alb, np.float32))
        off += len(V)

    app = make_appearance(r_app, sand)
    if texture is not None:
        from dataclasses import replace as _replace

        app = _replace(app, texture=texture)
    el = np.deg2rad(sun_elevation_deg if sun_elevation_deg is not None else r_sun.uniform(35, 60))
    az = r_sun.uniform(0, 2 * np.pi)
    if sun_azimuth_rad is not None:
        az = float(sun_azimuth_rad)
    sun = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
    return Scene(
        seed=int(seed), field=field_, terrain_axis_m=xs, terrain_xy=xy, terrain_tris=tris, terrain_spacing_m=spacing, rocks=rocks,
        pebble_vertices=np.concatenate(Vp) if Vp else np.zeros((0, 3)),
        pebble_tris=np.concatenate(Fp) if Fp else np.zeros((0, 3), np.int64),
        pebble_tri_scale=np.concatenate(Sp) if Sp else np.zeros(0, np.float32),
        appearance=app, sun_dir_site=sun,
    )
