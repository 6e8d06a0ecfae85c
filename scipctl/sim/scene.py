"""Synthetic Mars-like scenes with exact geometry: the assembled scene and its ray casting (Open3D).

Site frame: +x north, +y east, +z **down** (heights above the ground are
negative z). The scene's big target rock sits at the site origin (x, y) =
(0, 0); the terrain extends to +-150 m.

Content, all reproducible from ``make_scene(seed)``:

* terrain (:mod:`.terrain`): a triangulated height field ``z = -h(x, y)`` on a
  grid that is 2 cm near the target rock and grows geometrically outside.
* rocks (:mod:`.rocks`, meshes from :mod:`.mesh`): convex hulls of random points
  (faceted, with sharp corners), subdivided and roughened by 3-D noise, scaled to
  0.2 - 0.6 m, partly buried; one large target rock (~0.55 x 0.45 x 0.3 m) at the
  origin; other rocks are kept out of ``keep_clear`` corridors (the rover's
  approach paths).
* pebbles: small hulls (1 - 6 cm), dense near the target rock, sparse outside;
  none inside a few drift-sand patches near the rock.
* appearance (:mod:`.appearance`): Lambertian albedo that is a procedural
  function of the 3-D surface point, so it is the same from every viewpoint; the
  sun direction and an ambient term are part of the scene.

:class:`Scene` casts rays (:meth:`Scene.cast` -> :class:`Hits`, ``GEOM_*`` ids of
the three meshes), tests occlusion, interpolates the ground height and shades
(:meth:`Scene.radiance`).

Arrays: points ``(N, 3)`` site frame metres; ``xy`` ``(N, 2)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .appearance import MAT_PEBBLE, MAT_ROCK, MAT_SKY, MAT_TERRAIN, SPECK_MODES, Appearance, make_appearance
from .mesh import hull_mesh
from .noise import LatticeNoise
from .rocks import ROCK_SHAPES, Rock, make_rock
from .terrain import TERRAIN_KINDS, GridValues, HeightField, graded_axis, grid_mesh

GEOM_TERRAIN, GEOM_ROCKS, GEOM_PEBBLES = 0, 1, 2


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


def o3d_triangle_mesh(V: np.ndarray, F: np.ndarray):
    """An Open3D tensor ``TriangleMesh`` of vertices ``V`` ``(N, 3)`` (float32) and triangles ``F`` ``(M, 3)``."""
    from ..core.open3d_import import open3d

    o3d = open3d()

    m = o3d.t.geometry.TriangleMesh()
    m.vertex.positions = o3d.core.Tensor(np.ascontiguousarray(V, np.float32))
    m.triangle.indices = o3d.core.Tensor(np.ascontiguousarray(F, np.uint32))
    return m


def o3d_rays(origins: np.ndarray, dirs: np.ndarray):
    """Open3D rays ``(N, 6)`` float32 from ``origins`` and ``dirs`` ``(N, 3)``."""
    from ..core.open3d_import import open3d

    o3d = open3d()

    r = np.empty((len(origins), 6), np.float32)
    r[:, :3] = origins
    r[:, 3:] = dirs
    return o3d.core.Tensor(r)


@dataclass
class Scene:
    seed: int
    field: HeightField  # or a terrain.SlabField (same interface)
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

    def raycaster(self):
        """The Open3D ``RaycastingScene`` (built once): terrain, rocks, pebbles."""
        if self._rc is None:
            from ..core.open3d_import import open3d

            o3d = open3d()

            rc = o3d.t.geometry.RaycastingScene()
            ids = [
                rc.add_triangles(o3d_triangle_mesh(self.terrain_vertices(), self.terrain_tris)),
                rc.add_triangles(o3d_triangle_mesh(*self.rock_mesh()[:2])),
            ]
            if len(self.pebble_tris):
                ids.append(rc.add_triangles(o3d_triangle_mesh(self.pebble_vertices, self.pebble_tris)))
            if ids != list(range(len(ids))):
                raise RuntimeError(f"unexpected Open3D geometry ids {ids}")
            self._rc = rc
        return self._rc

    def _cast_raw(self, rc, origins, dirs):
        return rc.cast_rays(o3d_rays(origins, dirs))

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
        rays = o3d_rays(origins, np.broadcast_to(dirs, origins.shape))
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


def make_scene(seed: int, keep_clear=(), n_near_rocks: Optional[int] = None, sun_elevation_deg: Optional[float] = None,
               sun_azimuth_rad: Optional[float] = None, texture=None, terrain: str = "rolling", rock_shape: str = "faceted",
               sun_elevation_range_deg: tuple = (35.0, 60.0), specks: str = "lod") -> Scene:
    """A scene from ``seed`` (any int). ``keep_clear``: ``[(p0_xy, p1_xy, half_width_m), ...]`` corridors free of rocks.

    The target rock is ``scene.rocks[0]`` at the origin. ``sun_azimuth_rad``: direction (from north towards
    east) in which the sun stands; default random. ``sun_elevation_deg``: the sun's elevation; default drawn
    uniformly in ``sun_elevation_range_deg``. ``texture``: a :class:`~scipctl.sim.texture.SurfaceTexture`
    whose relative albedo replaces the procedural soil grain and specks (geometry and random draws unchanged).
    ``terrain``: a key of :data:`~scipctl.sim.terrain.TERRAIN_KINDS` (the height field, rocks, pebbles and sand
    around the rock); ``rock_shape``: a key of :data:`~scipctl.sim.rocks.ROCK_SHAPES`; ``n_near_rocks``
    overrides the terrain kind's count of rocks near the target; ``specks``: ``Appearance.specks`` (``lod`` or
    ``filtered``; random draws unchanged). The defaults make today's scene.
    """
    if terrain not in TERRAIN_KINDS:
        raise ValueError(f"terrain: unknown {terrain!r} (want one of {', '.join(TERRAIN_KINDS)})")
    if rock_shape not in ROCK_SHAPES:
        raise ValueError(f"rock_shape: unknown {rock_shape!r} (want one of {', '.join(ROCK_SHAPES)})")
    if specks not in SPECK_MODES:
        raise ValueError(f"specks: unknown {specks!r} (want one of {', '.join(SPECK_MODES)})")
    lo_el, hi_el = (float(v) for v in sun_elevation_range_deg)
    if not 0 < lo_el <= hi_el < 90:
        raise ValueError(f"sun_elevation_range_deg: want 0 < lo <= hi < 90, got {sun_elevation_range_deg}")
    shape = ROCK_SHAPES[rock_shape].check()
    ss = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, 0x5C1B])
    r_field, r_rock, r_peb, r_app, r_sun = (np.random.default_rng(s) for s in ss.spawn(5))
    ground = TERRAIN_KINDS[terrain](r_field)
    gp = ground.params.check()
    field_ = ground.field
    n_near_rocks = gp.near_rocks if n_near_rocks is None else int(n_near_rocks)
    xs = graded_axis()
    xy, tris, spacing = grid_mesh(xs, xs)
    lattice = LatticeNoise(r_rock, 48)

    rocks = []
    tsize = np.array([r_rock.uniform(0.52, 0.6), r_rock.uniform(0.42, 0.5), r_rock.uniform(0.28, 0.34) * shape.height_scale])
    rocks.append(make_rock("rock00", r_rock, lattice, field_, (0.0, 0.0), tsize, 34, 5, 0.012, r_rock.uniform(0.9, 1.15), True, 0.25,
                           shape=shape))
    # other rocks: a few near the target, more scattered further out, none in the corridors
    placed = [(np.zeros(2), rocks[0].radius_m)]

    def try_place(rmin, rmax, size_lo, size_hi, subdiv, tries=60):
        for _ in range(tries):
            rad = np.sqrt(r_rock.uniform(rmin ** 2, rmax ** 2))
            ang = r_rock.uniform(0, 2 * np.pi)
            c = np.array([rad * np.cos(ang), rad * np.sin(ang)])
            L = r_rock.uniform(size_lo, size_hi)
            sz = np.array([L, L * r_rock.uniform(0.6, 0.95), L * r_rock.uniform(0.35, 0.6) * shape.height_scale])
            rr = 0.5 * sz[0]
            if keep_clear and L > gp.corridor_rock_max_m and _dist_to_segments(c[None], keep_clear)[0] < rr + 0.15:
                continue
            if any(np.linalg.norm(c - pc) < rr + pr + 0.25 for pc, pr in placed):
                continue
            placed.append((c, rr))
            return c, sz, subdiv
        return None

    specs = []
    for _ in range(n_near_rocks):
        s = try_place(gp.near_rock_min_m, 4.0, *gp.near_rock_size_m, 4)
        if s:
            specs.append(s)
    for _ in range(gp.far_rock_tries):
        s = try_place(4.0, 25.0, *gp.far_rock_size_m, 3)
        if s:
            specs.append(s)
    for k, (c, sz, sd) in enumerate(specs, start=1):
        rocks.append(make_rock(f"rock{k:02d}", r_rock, lattice, field_, c, sz, int(r_rock.integers(16, 30)), sd, 0.015,
                               r_rock.uniform(0.75, 1.25), shape=shape))

    # drift-sand patches near the target rock (pebble-free)
    sand = []
    for _ in range(4 * gp.sand_patches):
        if len(sand) >= gp.sand_patches:
            break
        rad = r_peb.uniform(0.8, 2.2)
        ang = r_peb.uniform(0, 2 * np.pi)
        c = np.array([rad * np.cos(ang), rad * np.sin(ang)])
        R = r_peb.uniform(*gp.sand_radius_m)
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

    n_fine, n_coarse, n_outer = gp.pebble_counts
    k = gp.pebble_size_scale
    items = zone(n_fine, 0.35, 4.0, 0.01 * k, 0.03 * k, 0, 40) + zone(n_coarse, 0.35, 4.0, 0.03 * k, 0.07 * k, 40, 52) \
        + zone(n_outer, 4.0, 16.0, 0.02 * k, 0.08 * k, 0, 40)
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

    if gp.sand_sheet_m > 0:  # the sheet covers the ground (the appearance); pebbles above were kept out of the patches only
        sand = np.concatenate([sand, [[0.0, 0.0, gp.sand_sheet_m]]])
    app = make_appearance(r_app, sand)
    from dataclasses import replace as _replace

    if texture is not None:
        app = _replace(app, texture=texture)
    if specks != "lod":
        app = _replace(app, specks=specks)
    if gp.bedrock:  # the plates' exposure at the mesh's vertices, interpolated as the mesh is
        app = _replace(app, bedrock_exposure=GridValues(xs, field_.exposure(xy, spacing)))
    el = np.deg2rad(sun_elevation_deg if sun_elevation_deg is not None else r_sun.uniform(lo_el, hi_el))
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
