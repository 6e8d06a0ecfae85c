"""Pre-uplink prediction of tomorrow's single-cycle approach from today's downlink (docs/sequence.md).

From today's stereo (pancam/navcam pairs at the rover's current position) and
a designated 3-D target this module

1. builds a textured terrain mesh (:class:`Terrain`): each dense-stereo grid
   is triangulated (organised grid, long edges and grazing triangles dropped,
   :func:`grid_mesh`); a ray hit is textured by projecting the hit point into
   the source pair's original left image (full resolution); rocks are the
   cells that rise ``rock_height_m`` above a morphological-opening ground
   estimate (:meth:`Terrain.rock_cells`);
2. plans the approach (:func:`plan_approach`): stops every ``stop_fraction``
   of the remaining distance, pancam until the pancam->navcam handoff at
   ``pancam_handoff_m``, navcam stops, the turn to face the target and the
   navcam->hazcam handoff at ``hazcam_handoff_m``, hazcam stops and the final
   pose at ``standoff_m`` (target at the centre of the arm workspace); each
   stop's pose sits on the stereo terrain (plane fit under the footprint);
   straight approach first, detours to other approach bearings when rocks
   block it;
3. renders the expected view of every stop and camera (:meth:`Terrain.render`)
   and scores visibility: field of view, occlusion, texture, obliqueness;
4. runs a Monte Carlo over the pose-estimate error (:func:`monte_carlo`):
   per-leg position/yaw errors (random walk), the stereo re-estimate of the
   target at each stop, pointing from the estimate; gives P(in field of view),
   P(inside the tracker's search region), P(not occluded), P(in the arm
   workspace at the final pose) and the chain probability;
5. runs the tracking and handoff chain on rendered views for a few of those
   samples (:func:`simulate_chain`): NCC tracking with the chain's window
   sizes (``scipctl.pipeline.chain``), the pancam->navcam window scaling, and
   a navcam->hazcam handoff (kinematic point refined by an expected window
   draped from the navcam view), scored against the projection of the
   target's surface point;
6. names the stops and handoffs at risk and why (:func:`assess_risks`).

Frames: site frame (+x north, +y east, +z down) for the terrain, the target
and the planned poses; rover frame at each pose (+x forward, +y right, +z
down). Headings (yaw) are about +z down: from north towards east.
Everything numeric here is pure (arrays in, arrays out); Open3D and OpenCV
are imported inside functions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Optional

import numpy as np

from ..core.camera import CameraModel
from ..core.kinematics import RoverConfig, RoverPose
from ..core.transforms import RigidTransform, axis_angle_to_matrix, matrix_to_euler_zyx

# chain window sizes (kept identical to the on-board chain simulation)
from .chain import SEARCH_RADIUS_PX, TEMPLATE_HALF_PX

HANDOFF_TEMPLATE_HALF_PX = 15  # navcam -> hazcam expected window (HandoffParams default)
HANDOFF_SEARCH_RADIUS_PX = 60.0
FOV_MARGIN_PX = {"pancam": 24, "navcam": 20, "hazcam": 20}
# a tracked pixel is accurate when it lies this close to the target on the surface (the paper's goal is 1 cm
# at the hazcams), or within MIN_SUCCESS_PX; farther than LOST_M the chain has lost the target
SUCCESS_M = {"pancam": 0.02, "navcam": 0.02, "hazcam": 0.01}
MIN_SUCCESS_PX = 1.0
LOST_M = 0.05


# ============================================================================ parameters
@dataclass(frozen=True)
class ArmWorkspace:
    """Where the arm can place its instrument, in the rover frame at the final pose (a simple documented model).

    The target's horizontal position ``(x forward, y right)`` must satisfy
    ``r_min_m <= hypot(x, y) <= r_max_m``, ``x > 0`` and ``|y| <= half_width_m``
    (an annulus sector ahead of the rover origin).
    """

    r_min_m: float = 0.6
    r_max_m: float = 1.0
    half_width_m: float = 0.4

    @property
    def centre_m(self) -> float:
        return 0.5 * (self.r_min_m + self.r_max_m)

    def contains(self, xy_rover) -> np.ndarray:
        """``xy_rover`` (..., 2) horizontal rover-frame positions -> (...,) bool."""
        p = np.asarray(xy_rover, float)
        if p.shape[-1] != 2:
            raise ValueError(f"xy_rover: expected (..., 2), got {p.shape}")
        r = np.hypot(p[..., 0], p[..., 1])
        return (r >= self.r_min_m) & (r <= self.r_max_m) & (p[..., 0] > 0) & (np.abs(p[..., 1]) <= self.half_width_m)


@dataclass(frozen=True)
class RoverBody:
    """The rover's footprint in its own frame: the rectangle ``rear_m <= x <= front_m``, ``|y| <= half_width_m``."""

    front_m: float = 0.5
    rear_m: float = -0.5
    half_width_m: float = 0.4

    def distance(self, xy_rover) -> np.ndarray:
        """Horizontal distance (m) of rover-frame points ``(..., 2)`` from the footprint (0 inside)."""
        p = np.asarray(xy_rover, float)
        if p.shape[-1] != 2:
            raise ValueError(f"xy_rover: expected (..., 2), got {p.shape}")
        dx = np.maximum(np.maximum(self.rear_m - p[..., 0], p[..., 0] - self.front_m), 0.0)
        dy = np.maximum(np.abs(p[..., 1]) - self.half_width_m, 0.0)
        return np.hypot(dx, dy)

    def corners(self) -> np.ndarray:
        """(4, 2) footprint corners, rover frame."""
        return np.array([[self.front_m, -self.half_width_m], [self.front_m, self.half_width_m],
                         [self.rear_m, self.half_width_m], [self.rear_m, -self.half_width_m]])


@dataclass(frozen=True)
class ApproachParams:
    """How the approach is planned (distances are horizontal, rover origin to target)."""

    stop_fraction: float = 0.15  # a stop after every ~15 % of the remaining distance
    min_leg_m: float = 0.3
    merge_m: float = 0.25  # regular stops this close to a special stop are dropped
    pancam_handoff_m: float = 4.5
    hazcam_handoff_m: float = 2.0
    hazcam_stops_m: tuple = (1.4,)
    standoff_m: Optional[float] = None  # final distance; None: the arm workspace centre
    detour_bearings_rad: tuple = tuple(np.deg2rad([0.0, 15.0, -15.0, 30.0, -30.0, 45.0, -45.0]).tolist())
    path_step_m: float = 0.05
    turn_step_rad: float = math.radians(10.0)
    rock_height_m: float = 0.15  # rocks at least this tall (above the local ground) are obstacles
    rock_cell_m: float = 0.05
    ground_window_m: float = 1.0
    rock_keep_out_m: float = 0.15
    target_keep_out_m: float = 0.25
    arm: ArmWorkspace = field(default_factory=ArmWorkspace)
    body: RoverBody = field(default_factory=RoverBody)

    @property
    def final_distance_m(self) -> float:
        return self.arm.centre_m if self.standoff_m is None else float(self.standoff_m)


@dataclass(frozen=True)
class UncertaintyParams:
    """Pose-estimate error model for the Monte Carlo (1-sigma, per stop, relative to the previous stop).

    ``sigma_position_m`` / ``sigma_yaw_rad``: ``None`` takes them from the
    downlink pose of today's image (``sigma_position_m``, ``sigma_yaw_rad``),
    else the defaults. Each leg adds ``drive_error_frac`` x leg length (m)
    and ``yaw_error_rad_per_m`` x leg length in quadrature. The target's 3-D
    re-estimate at each stop has range noise ``r^2 sigma_d / (f b)``.
    """

    sigma_position_m: Optional[float] = None
    sigma_yaw_rad: Optional[float] = None
    default_sigma_position_m: float = 0.01
    default_sigma_yaw_rad: float = math.radians(0.5)
    drive_error_frac: float = 0.05  # wheel odometry: a few % of the distance driven
    yaw_error_rad_per_m: float = math.radians(1.0)  # heading drift per metre
    disparity_sigma_px: float = 0.25
    n_samples: int = 1000
    n_track_samples: int = 8
    seed: int = 0


@dataclass(frozen=True)
class PredictParams:
    approach: ApproachParams = field(default_factory=ApproachParams)
    uncertainty: UncertaintyParams = field(default_factory=UncertaintyParams)
    render_width_px: int = 256  # nominal expected views (for reports)
    stereo_downsample: int = 2
    max_edge_ratio: float = 20.0  # grid-mesh edge longer than this x its angular footprint: a depth discontinuity
    min_edge_m: float = 0.03
    smooth_sigma_px: float = 1.5  # stereo grids are smoothed along their rays before meshing (smooth_grid)
    occlusion_tol_m: float = 0.04
    low_texture_std: float = 0.015  # std of the expected window (0..1 units) below which texture is "low"
    min_coverage: float = 0.6  # fraction of the expected window the terrain covers
    max_incidence_rad: float = math.radians(85.0)  # grazing view of the target surface
    max_foreshortening_change: float = 2.0  # cos(incidence) ratio between consecutive images of the chain
    risk_probability: float = 0.9  # a stop/handoff whose probability is below this is at risk
    run_chain: bool = True
    search_margin_px: float = 40.0  # chain sim: rendered search region = true offset + this (see docs)


# ============================================================================ small geometry
def scaled_model(model: CameraModel, scale: float) -> CameraModel:
    """The model of the same camera with its image resampled by ``scale`` (pixel centres: ``u' = s (u + 0.5) - 0.5``)."""
    s = float(scale)
    if not s > 0:
        raise ValueError(f"scale: must be > 0, got {scale}")
    k = (s - 1.0) / 2.0
    return replace(model, H=s * model.H + k * model.A, V=s * model.V + k * model.A)


def pose_on_plane(xy_site, yaw_rad: float, plane) -> RigidTransform:
    """``T_site_rover`` for a rover at horizontal ``xy_site`` (2,) heading ``yaw_rad`` resting on ``plane``.

    ``plane = (a, b, c)``: the ground ``z = a x + b y + c`` (site frame, z down).
    The rover z axis is the plane's downward normal; its x axis is the heading
    projected onto the plane.
    """
    a, b, c = (float(v) for v in plane)
    x, y = (float(v) for v in np.asarray(xy_site, float).reshape(2))
    n = np.array([-a, -b, 1.0])
    n /= np.linalg.norm(n)  # down normal (site z is down)
    h = np.array([math.cos(yaw_rad), math.sin(yaw_rad), 0.0])
    xa = h - np.dot(h, n) * n
    xa /= np.linalg.norm(xa)
    ya = np.cross(n, xa)
    R = np.stack([xa, ya, n], axis=1)
    return RigidTransform(R, np.array([x, y, a * x + b * y + c]))


def yaw_of(T_site_rover: RigidTransform) -> float:
    return float(matrix_to_euler_zyx(T_site_rover.R)[0])


def tilt_of(T_site_rover: RigidTransform) -> float:
    """Angle (rad) between the rover's z axis and the site vertical."""
    return float(math.acos(np.clip(T_site_rover.R[2, 2], -1.0, 1.0)))


def _wrap(a):
    return (np.asarray(a, float) + np.pi) % (2 * np.pi) - np.pi


def perturb_pose(T_site_rover: RigidTransform, dxy_rover, dyaw_rad) -> list:
    """Poses ``T_site_rover @ Exp(d)`` for errors ``dxy_rover`` (N, 2) (rover frame) and ``dyaw_rad`` (N,)."""
    d = np.asarray(dxy_rover, float).reshape(-1, 2)
    y = np.asarray(dyaw_rad, float).reshape(-1)
    out = []
    for k in range(len(d)):
        D = RigidTransform(axis_angle_to_matrix([0, 0, 1], y[k]), np.array([d[k, 0], d[k, 1], 0.0]))
        out.append(T_site_rover @ D)
    return out


# ============================================================================ terrain
def grid_mesh(xyz: np.ndarray, centre_m, max_edge_ratio: float = 20.0, min_edge_m: float = 0.03):
    """Triangulate an organised point grid ``xyz`` (h, w, 3) (NaN invalid) seen from ``centre_m`` (3,).

    Each grid quad gives two triangles whose three vertices are valid. An edge
    is a depth discontinuity (and its triangle is dropped) when it is longer
    than ``max(min_edge_m, max_edge_ratio * r * angle)``, where ``r`` is the
    mean range of its ends and ``angle`` the angle their rays subtend at the
    camera (a surface seen at incidence ``i`` has ratio ``1 / cos i``; 20
    keeps surfaces up to ~87 deg). Returns ``(vertices (N, 3), triangles (M, 3)
    int64, vertex_grid_index (N,))`` with only the used vertices.
    """
    P = np.asarray(xyz, float)
    if P.ndim != 3 or P.shape[2] != 3:
        raise ValueError(f"xyz: expected (h, w, 3), got {P.shape}")
    h, w, _ = P.shape
    C = np.asarray(centre_m, float).reshape(3)
    valid = np.all(np.isfinite(P), axis=2)
    rng = np.where(valid, np.linalg.norm(P - C, axis=2), np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        dirs = (P - C) / rng[..., None]

    def edge_ok(i0, i1):
        # i0, i1: (slices) of the grid -> bool
        a, b = P[i0], P[i1]
        L = np.linalg.norm(a - b, axis=-1)
        cosang = np.clip(np.sum(dirs[i0] * dirs[i1], axis=-1), -1.0, 1.0)
        ang = np.arccos(cosang)
        rmean = 0.5 * (rng[i0] + rng[i1])
        lim = np.maximum(min_edge_m, max_edge_ratio * rmean * ang)
        with np.errstate(invalid="ignore"):
            return valid[i0] & valid[i1] & (L <= lim)

    s00 = (slice(0, h - 1), slice(0, w - 1))
    s01 = (slice(0, h - 1), slice(1, w))
    s10 = (slice(1, h), slice(0, w - 1))
    s11 = (slice(1, h), slice(1, w))
    top = edge_ok(s00, s01)
    left = edge_ok(s00, s10)
    diag = edge_ok(s01, s10)
    bottom = edge_ok(s10, s11)
    right = edge_ok(s01, s11)
    idx = np.arange(h * w).reshape(h, w)
    t1 = top & left & diag  # (00, 01, 10)
    t2 = diag & right & bottom  # (01, 11, 10)
    tri1 = np.stack([idx[s00][t1], idx[s10][t1], idx[s01][t1]], axis=1)
    tri2 = np.stack([idx[s01][t2], idx[s10][t2], idx[s11][t2]], axis=1)
    tris = np.concatenate([tri1, tri2], axis=0)
    used = np.unique(tris)
    remap = np.full(h * w, -1, np.int64)
    remap[used] = np.arange(len(used))
    verts = P.reshape(-1, 3)[used]
    return verts, remap[tris], used


def smooth_grid(xyz: np.ndarray, centre_m, sigma_px: float = 1.5, max_rel: float = 0.03) -> np.ndarray:
    """Smooth an organised point grid ``xyz`` (h, w, 3) (NaN invalid) along its rays from ``centre_m`` (3,).

    Each range is replaced by the Gaussian-weighted mean (``sigma_px`` grid
    cells, window ``+-ceil(2 sigma)``) of the valid neighbours whose range is
    within ``max_rel`` (relative) of its own: a range-gated ("bilateral")
    filter, so depth discontinuities stay sharp. Points move only along their
    own rays (their pixels do not change). Returns a new (h, w, 3) array.
    """
    P = np.asarray(xyz, float)
    if P.ndim != 3 or P.shape[2] != 3:
        raise ValueError(f"xyz: expected (h, w, 3), got {P.shape}")
    if sigma_px <= 0:
        return P.copy()
    C = np.asarray(centre_m, float).reshape(3)
    h, w, _ = P.shape
    valid = np.all(np.isfinite(P), axis=2)
    r = np.where(valid, np.linalg.norm(P - C, axis=2), np.nan)
    k = int(math.ceil(2 * sigma_px))
    rp = np.pad(r, k, constant_values=np.nan)
    num = np.zeros((h, w))
    den = np.zeros((h, w))
    for dy in range(-k, k + 1):
        for dx in range(-k, k + 1):
            g = math.exp(-(dx * dx + dy * dy) / (2 * sigma_px * sigma_px))
            rn = rp[k + dy:k + dy + h, k + dx:k + dx + w]
            with np.errstate(invalid="ignore"):
                m = np.abs(rn - r) <= max_rel * r
            num += np.where(m, g * rn, 0.0)
            den += np.where(m, g, 0.0)
    out = P.copy()
    use = valid & (den > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rs = num / den
        dirs = (P - C) / np.where(valid, r, 1.0)[..., None]
    out[use] = C + rs[use][:, None] * dirs[use]
    return out


@dataclass
class TerrainSource:
    """One stereo pair's contribution: its grid (site frame), the original left image and model (site frame)."""

    name: str  # e.g. the left product id
    camera: str
    xyz_site: np.ndarray  # (h, w, 3) NaN invalid
    left_img: np.ndarray  # (H, W) float32 original left image
    left_model_site: CameraModel
    centre_site: np.ndarray  # (3,) the rectified left camera centre (site frame)
    priority: int = 0  # lower wins where sources overlap (pancam before navcam)


@dataclass
class RayHits:
    hit: np.ndarray  # (N,) bool
    t_m: np.ndarray  # (N,) distance along the unit ray (inf where no hit)
    source: np.ndarray  # (N,) int source index (-1 where no hit)
    points: np.ndarray  # (N, 3) hit points (NaN where no hit)
    normals: np.ndarray  # (N, 3) unit triangle normals (NaN where no hit)


@dataclass
class RenderedView:
    """An expected image: ``image`` (h, w) float32 in the source images' units (NaN where the terrain is unknown)."""

    image: np.ndarray
    depth_m: np.ndarray  # (h, w) distance along each ray, NaN where unknown
    origin_uv: tuple  # full-image pixel of image[0, 0]
    model: CameraModel  # site frame, at the rendered resolution

    @property
    def coverage(self) -> float:
        return float(np.isfinite(self.image).mean()) if self.image.size else 0.0


class Terrain:
    """Today's stereo terrain: a textured triangle mesh in the site frame, with rock cells and ground planes."""

    def __init__(self, sources: list, max_edge_ratio: float = 20.0, min_edge_m: float = 0.03, smooth_sigma_px: float = 1.5):
        if not sources:
            raise ValueError("terrain: no stereo sources")
        self.sources = sorted(sources, key=lambda s: s.priority)
        verts, tris, tri_src = [], [], []
        off = 0
        covered = []  # (source, mask over its image) for the priority rule
        for si, s in enumerate(self.sources):
            xyz = smooth_grid(s.xyz_site, s.centre_site, smooth_sigma_px)
            # a lower-priority source drops points that a higher-priority source already sees
            for hs, hv in covered:
                flat = xyz.reshape(-1, 3)
                ok = np.all(np.isfinite(flat), axis=1)
                if not np.any(ok):
                    break
                uv = hs.left_model_site.project(flat[ok])
                inside = _inside_mask(uv, hv)
                sel = np.flatnonzero(ok)[inside]
                flat[sel] = np.nan
                xyz = flat.reshape(xyz.shape)
            v, t, _ = grid_mesh(xyz, s.centre_site, max_edge_ratio, min_edge_m)
            if len(t):
                verts.append(v)
                tris.append(t + off)
                tri_src.append(np.full(len(t), si, np.int32))
                off += len(v)
            covered.append((s, _coverage_mask(s)))
        if not tris:
            raise ValueError("terrain: the stereo grids give no triangles")
        self.vertices = np.concatenate(verts).astype(np.float64)
        self.triangles = np.concatenate(tris).astype(np.int64)
        self.triangle_source = np.concatenate(tri_src)
        self._ref = self.vertices.mean(axis=0)  # the caster works in float32 relative to this point
        self._scene = None
        self._rock_cache = {}

    # ------------------------------------------------------------------ casting
    def _raycaster(self):
        if self._scene is None:
            import open3d as o3d

            sc = o3d.t.geometry.RaycastingScene()
            sc.add_triangles(o3d.core.Tensor((self.vertices - self._ref).astype(np.float32)),
                             o3d.core.Tensor(self.triangles.astype(np.uint32)))
            self._scene = sc
        return self._scene

    def cast(self, origins, directions) -> RayHits:
        """Cast rays ``origins`` (N, 3), unit ``directions`` (N, 3) (site frame) into the mesh."""
        import open3d as o3d

        o = np.asarray(origins, float).reshape(-1, 3)
        d = np.asarray(directions, float).reshape(-1, 3)
        if o.shape != d.shape:
            raise ValueError(f"origins {o.shape} and directions {d.shape} differ")
        n = len(o)
        hits = RayHits(np.zeros(n, bool), np.full(n, np.inf), np.full(n, -1, np.int32),
                       np.full((n, 3), np.nan), np.full((n, 3), np.nan))
        good = np.all(np.isfinite(o), axis=1) & np.all(np.isfinite(d), axis=1)
        if not np.any(good):
            return hits
        # cast relative to a local origin (float32 precision in the caster)
        rays = np.concatenate([o[good] - self._ref, d[good]], axis=1).astype(np.float32)
        res = self._raycaster().cast_rays(o3d.core.Tensor(rays))
        t = res["t_hit"].numpy().astype(float)
        prim = res["primitive_ids"].numpy().astype(np.int64)
        nrm = res["primitive_normals"].numpy().astype(float)
        ok = np.isfinite(t)
        gi = np.flatnonzero(good)
        hits.hit[gi] = ok
        hits.t_m[gi[ok]] = t[ok]
        hits.source[gi[ok]] = self.triangle_source[prim[ok]]
        hits.points[gi[ok]] = o[gi[ok]] + t[ok, None] * d[gi[ok]]
        hits.normals[gi[ok]] = nrm[ok]
        return hits

    def texture(self, hits: RayHits) -> np.ndarray:
        """Intensity at each hit (N,): the hit point projected into its source's original left image."""
        from ..core.expected import bilinear_sample

        out = np.full(len(hits.hit), np.nan, np.float32)
        for si, s in enumerate(self.sources):
            sel = hits.hit & (hits.source == si)
            if np.any(sel):
                uv = s.left_model_site.project(hits.points[sel])
                out[sel] = bilinear_sample(s.left_img, uv)
        return out

    def render(self, model_site: CameraModel, width: int, height: int, roi: Optional[tuple] = None) -> RenderedView:
        """Expected image through ``model_site`` (site frame) of a ``width`` x ``height`` camera.

        ``roi = (u0, v0, w, h)``: only that window (pixel ``image[0, 0]`` is ``(u0, v0)``;
        it may extend beyond the image).
        """
        u0, v0, w, h = roi if roi is not None else (0, 0, int(width), int(height))
        us, vs = np.meshgrid(np.arange(u0, u0 + w, dtype=float), np.arange(v0, v0 + h, dtype=float))
        uv = np.stack([us, vs], axis=-1).reshape(-1, 2)
        o, d = model_site.unproject(uv)
        hits = self.cast(o, d)
        img = self.texture(hits).reshape(h, w)
        depth = np.where(hits.hit, hits.t_m, np.nan).reshape(h, w).astype(np.float32)
        return RenderedView(img, depth, (u0, v0), model_site)

    def occluded(self, origins, targets, tol_m: float = 0.04) -> np.ndarray:
        """(N,) bool: the segment from ``origins`` (N, 3) to ``targets`` (N, 3) meets the terrain before the target."""
        o = np.asarray(origins, float).reshape(-1, 3)
        X = np.asarray(targets, float).reshape(-1, 3)
        v = X - o
        dist = np.linalg.norm(v, axis=1)
        hits = self.cast(o, v / dist[:, None])
        tol = np.maximum(tol_m, 0.02 * dist)
        return hits.hit & (hits.t_m < dist - tol)

    def surface_point(self, origin, direction) -> Optional[np.ndarray]:
        h = self.cast(np.asarray(origin, float)[None], np.asarray(direction, float)[None])
        return h.points[0] if h.hit[0] else None

    # ------------------------------------------------------------------ ground and rocks
    def height_grid(self, cell_m: float):
        """Cell statistics of the vertices: ``(x0, y0, max_up (ny, nx), med_z (ny, nx), count (ny, nx))``.

        ``max_up`` is the highest point (``-z``) per cell, ``med_z`` the median
        site z; NaN where a cell has no vertex.
        """
        key = ("grid", float(cell_m))
        if key in self._rock_cache:
            return self._rock_cache[key]
        P = self.vertices
        x0, y0 = P[:, 0].min(), P[:, 1].min()
        ix = np.floor((P[:, 0] - x0) / cell_m).astype(np.int64)
        iy = np.floor((P[:, 1] - y0) / cell_m).astype(np.int64)
        nx, ny = int(ix.max()) + 1, int(iy.max()) + 1
        flat = iy * nx + ix
        up = -P[:, 2]
        max_up = np.full(nx * ny, -np.inf)
        np.maximum.at(max_up, flat, up)
        count = np.bincount(flat, minlength=nx * ny)
        # median z per cell via sorting
        order = np.lexsort((P[:, 2], flat))
        fs = flat[order]
        zs = P[order, 2]
        starts = np.searchsorted(fs, np.arange(nx * ny), side="left")
        med = np.full(nx * ny, np.nan)
        has = count > 0
        mid = starts[has] + count[has] // 2
        med[has] = zs[mid]
        max_up[~has] = np.nan
        with np.errstate(invalid="ignore", divide="ignore"):
            means = np.stack([np.bincount(flat, weights=P[:, k], minlength=nx * ny) / count for k in range(3)], axis=1)
        self._rock_cache[("means", float(cell_m))] = means.reshape(ny, nx, 3)
        out = (float(x0), float(y0), max_up.reshape(ny, nx), med.reshape(ny, nx), count.reshape(ny, nx))
        self._rock_cache[key] = out
        return out

    def rock_cells(self, cell_m: float = 0.05, ground_window_m: float = 1.0, min_height_m: float = 0.15) -> np.ndarray:
        """Centres ``(K, 2)`` (site x, y) of cells whose highest point rises ``min_height_m`` above the ground.

        Ground: a grey-scale opening (erosion then dilation with a square of
        side ``ground_window_m``) of the per-cell lowest surface, which keeps
        planes and removes bumps narrower than the window.
        """
        import cv2

        key = ("rocks", float(cell_m), float(ground_window_m), float(min_height_m))
        if key in self._rock_cache:
            return self._rock_cache[key]
        x0, y0, max_up, med_z, _ = self.height_grid(cell_m)
        low_up = -med_z  # median height per cell as the local surface
        k = max(3, int(round(ground_window_m / cell_m)) | 1)
        se = np.ones((k, k), np.uint8)
        big = np.float32(1e6)
        a = np.where(np.isfinite(low_up), low_up, big).astype(np.float32)
        er = cv2.erode(a, se, borderType=cv2.BORDER_CONSTANT, borderValue=float(big))
        er = np.where(er >= big / 2, -big, er).astype(np.float32)
        ground = cv2.dilate(er, se, borderType=cv2.BORDER_CONSTANT, borderValue=float(-big))
        known = np.isfinite(max_up) & (ground > -big / 2)
        with np.errstate(invalid="ignore"):
            rock = known & (max_up - ground >= min_height_m)
        iy, ix = np.nonzero(rock)
        out = np.stack([x0 + (ix + 0.5) * cell_m, y0 + (iy + 0.5) * cell_m], axis=1)
        self._rock_cache[key] = out
        return out

    def ground_plane(self, T_site_rover_guess: RigidTransform, body: RoverBody, cell_m: float = 0.05,
                     min_cells: int = 12):
        """Plane ``(a, b, c)`` (``z = a x + b y + c``, site) fitted to the cell means under the footprint.

        Returns ``(plane or None, n_cells, known_fraction)``.
        """
        x0, y0, _, med_z, _ = self.height_grid(cell_m)
        means = self._rock_cache[("means", float(cell_m))]
        ny, nx = med_z.shape
        corners = T_site_rover_guess.apply(np.c_[body.corners(), np.zeros(4)])[:, :2]
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        i0, i1 = int(np.floor((lo[0] - x0) / cell_m)), int(np.ceil((hi[0] - x0) / cell_m))
        j0, j1 = int(np.floor((lo[1] - y0) / cell_m)), int(np.ceil((hi[1] - y0) / cell_m))
        i0, j0 = max(i0, 0), max(j0, 0)
        i1, j1 = min(i1, nx), min(j1, ny)
        area_cells = (body.front_m - body.rear_m) * 2 * body.half_width_m / (cell_m * cell_m)
        if i1 <= i0 or j1 <= j0:
            return None, 0, 0.0
        jj, ii = np.mgrid[j0:j1, i0:i1]
        xs = x0 + (ii + 0.5) * cell_m
        ys = y0 + (jj + 0.5) * cell_m
        mm = means[j0:j1, i0:i1].reshape(-1, 3)
        pts = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
        local = T_site_rover_guess.inverse().apply(pts)[:, :2]
        inside = body.distance(local) <= 0.0
        zz = mm[:, 2]
        use = inside & np.all(np.isfinite(mm), axis=1)
        n = int(use.sum())
        frac = float(min(1.0, n / max(area_cells, 1.0)))
        if n < min_cells:
            return None, n, frac
        A = np.c_[mm[use, 0], mm[use, 1], np.ones(n)]
        # robust: two passes, dropping cells more than 5 cm off the first plane (rocks under the footprint)
        sol = np.linalg.lstsq(A, zz[use], rcond=None)[0]
        res = np.abs(A @ sol - zz[use])
        keep = res < max(0.05, 3 * np.median(res))
        if keep.sum() >= min_cells:
            sol = np.linalg.lstsq(A[keep], zz[use][keep], rcond=None)[0]
        return (float(sol[0]), float(sol[1]), float(sol[2])), n, frac

    def known_fraction_along(self, xy_site, cell_m: float = 0.25) -> float:
        """Fraction of the points ``xy_site`` (N, 2) that fall in cells (side ``cell_m``) holding terrain vertices."""
        P = np.asarray(xy_site, float).reshape(-1, 2)
        if not len(P):
            return 1.0
        x0, y0, _, _, count = self.height_grid(cell_m)
        ny, nx = count.shape
        ix = np.floor((P[:, 0] - x0) / cell_m).astype(int)
        iy = np.floor((P[:, 1] - y0) / cell_m).astype(int)
        ok = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny)
        known = np.zeros(len(P), bool)
        known[ok] = count[iy[ok], ix[ok]] > 0
        return float(known.mean())


def _inside_mask(uv: np.ndarray, mask: np.ndarray) -> np.ndarray:
    h, w = mask.shape
    u = np.floor(uv[:, 0] + 0.5)
    v = np.floor(uv[:, 1] + 0.5)
    ok = np.isfinite(u) & np.isfinite(v) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
    out = np.zeros(len(uv), bool)
    out[ok] = mask[v[ok].astype(int), u[ok].astype(int)]
    return out


def _coverage_mask(s: TerrainSource) -> np.ndarray:
    """Original-left-image pixels that the source's valid grid covers (dilated a little)."""
    import cv2

    H, W = s.left_img.shape
    mask = np.zeros((H, W), np.uint8)
    flat = s.xyz_site.reshape(-1, 3)
    ok = np.all(np.isfinite(flat), axis=1)
    if np.any(ok):
        uv = s.left_model_site.project(flat[ok])
        u = np.floor(uv[:, 0] + 0.5)
        v = np.floor(uv[:, 1] + 0.5)
        g = np.isfinite(u) & np.isfinite(v) & (u >= 0) & (u < W) & (v >= 0) & (v < H)
        mask[v[g].astype(int), u[g].astype(int)] = 1
        mask = cv2.dilate(mask, np.ones((5, 5), np.uint8))
    return mask.astype(bool)


# ============================================================================ planning
@dataclass
class CameraShot:
    """One camera's acquisition at a stop, as planned (nominal: no pose error)."""

    camera: str
    pan_rad: Optional[float]
    tilt_rad: Optional[float]
    uv: Optional[list]  # predicted left-image pixel of the target
    range_m: Optional[float]
    in_fov: bool
    incidence_rad: Optional[float] = None
    occluded: Optional[bool] = None
    texture_std: Optional[float] = None
    coverage: Optional[float] = None
    template_half_px: int = 15
    search_radius_px: float = 60.0
    note: str = ""

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class PlannedStop:
    index: int
    kind: str  # start | pancam | pancam-navcam-handoff | navcam | navcam-hazcam-handoff | hazcam | final
    distance_m: float  # horizontal, rover origin -> target
    T_site_rover: RigidTransform
    heading_rad: float
    leg_m: float  # path length driven from the previous stop
    turn_rad: float  # turn in place before imaging (the turn to face the target, or at a waypoint)
    cameras: list = field(default_factory=list)  # CameraShot
    tilt_rad: float = 0.0
    terrain_known: bool = True
    path_from_previous: list = field(default_factory=list)  # [(x, y), ...] site frame, incl. both ends

    @property
    def position_m(self) -> np.ndarray:
        return self.T_site_rover.t

    def to_dict(self) -> dict:
        return {
            "index": self.index, "kind": self.kind, "distance_m": self.distance_m,
            "position_site_m": self.T_site_rover.t.tolist(), "orientation_wxyz": self.T_site_rover.quat_wxyz.tolist(),
            "heading_rad": self.heading_rad, "leg_m": self.leg_m, "turn_rad": self.turn_rad,
            "tilt_rad": self.tilt_rad, "terrain_known": self.terrain_known,
            "cameras": [c.to_dict() for c in self.cameras],
        }


@dataclass
class ApproachPlan:
    target_site_m: np.ndarray  # (3,)
    start: RoverPose
    bearing_rad: float  # final approach heading
    detour_rad: float  # bearing minus the direct bearing
    stops: list  # PlannedStop, stops[0] is today's position
    path_xy: np.ndarray  # (N, 2) the whole path, site frame
    path_length_m: float
    clearance: dict  # min distances: rocks, target; blocked flag
    params: ApproachParams
    designation_camera: str = "pancam"

    @property
    def final(self) -> PlannedStop:
        return self.stops[-1]

    def to_dict(self) -> dict:
        return {
            "target_site_m": self.target_site_m.tolist(), "bearing_rad": self.bearing_rad, "detour_rad": self.detour_rad,
            "path_length_m": self.path_length_m, "clearance": self.clearance,
            "stops": [s.to_dict() for s in self.stops],
        }


def stop_distances(start_m: float, p: ApproachParams, designation_camera: str = "pancam") -> list:
    """Planned stop distances (m, decreasing, last = the final standoff) and their kinds.

    Special stops at ``pancam_handoff_m`` (when starting beyond it with
    pancams), ``hazcam_handoff_m``, ``hazcam_stops_m`` and the final standoff;
    above the navcam->hazcam handoff, regular stops every ``stop_fraction`` of
    the remaining distance (at least ``min_leg_m``) from the previous stop; a
    regular stop that would fall within ``merge_m`` of the next special stop
    is replaced by it.
    """
    d_final = p.final_distance_m
    if not start_m > d_final:
        return []
    specials = {}
    if designation_camera == "pancam" and start_m > p.pancam_handoff_m + p.merge_m:
        specials[p.pancam_handoff_m] = "pancam-navcam-handoff"
    if start_m > p.hazcam_handoff_m + p.merge_m:
        specials[p.hazcam_handoff_m] = "navcam-hazcam-handoff"
    for d in p.hazcam_stops_m:
        if d_final + p.merge_m < d < min(start_m, p.hazcam_handoff_m) - p.merge_m:
            specials[float(d)] = "hazcam"
    specials[d_final] = "final"
    out = []
    d = start_m
    while d > d_final:
        below = [x for x in specials if x < d - 1e-9]
        s_next = max(below)
        cand = d - max(p.stop_fraction * d, p.min_leg_m)
        if d <= p.hazcam_handoff_m + 1e-9 or cand <= s_next + p.merge_m:
            d = s_next
            out.append((float(d), specials[d]))
        else:
            d = cand
            kind = "pancam" if (designation_camera == "pancam" and d > p.pancam_handoff_m) else "navcam"
            out.append((float(d), kind))
    # a start already inside the pancam->navcam handoff distance hands off at the first stop
    if designation_camera == "pancam" and start_m <= p.pancam_handoff_m + p.merge_m and out:
        if out[0][1] == "navcam":
            out[0] = (out[0][0], "pancam-navcam-handoff")
    return out


def _cameras_for(kind: str) -> list:
    return {
        "pancam": ["pancam"], "pancam-navcam-handoff": ["pancam", "navcam"], "navcam": ["navcam"],
        "navcam-hazcam-handoff": ["navcam", "hazcam"], "hazcam": ["hazcam"], "final": ["hazcam"],
    }[kind]


def _point_on_polyline_at_distance(poly: np.ndarray, T_xy: np.ndarray, dist: float, s_from: float = 0.0):
    """First point (arc length s >= s_from) of the polyline ``poly`` (N, 2) at horizontal ``dist`` from ``T_xy``.

    Returns ``(point (2,), s, segment index)`` or None.
    """
    s0 = 0.0
    for i in range(len(poly) - 1):
        a, b = poly[i], poly[i + 1]
        L = float(np.linalg.norm(b - a))
        if L < 1e-12:
            continue
        u = (b - a) / L
        # |a + t u - T|^2 = dist^2
        w = a - T_xy
        bq = 2 * np.dot(u, w)
        cq = np.dot(w, w) - dist * dist
        disc = bq * bq - 4 * cq
        if disc >= 0:
            for t in sorted(((-bq - math.sqrt(disc)) / 2, (-bq + math.sqrt(disc)) / 2)):
                if -1e-9 <= t <= L + 1e-9 and s0 + t >= s_from - 1e-9:
                    return a + t * u, s0 + t, i
        s0 += L
    return None


def _sample_path_poses(poly: np.ndarray, step_m: float) -> tuple:
    """Points (N, 2) and headings (N,) every ``step_m`` along a polyline (segments' own headings)."""
    pts, yaws = [], []
    for i in range(len(poly) - 1):
        a, b = poly[i], poly[i + 1]
        L = float(np.linalg.norm(b - a))
        if L < 1e-9:
            continue
        yaw = math.atan2(b[1] - a[1], b[0] - a[0])
        n = max(1, int(math.ceil(L / step_m)))
        for t in np.linspace(0.0, 1.0, n + 1):
            pts.append(a + t * (b - a))
            yaws.append(yaw)
    return np.array(pts).reshape(-1, 2), np.array(yaws)


def _turn_samples(xy, yaw_from, yaw_to, step_rad):
    d = float(_wrap(yaw_to - yaw_from))
    n = max(1, int(math.ceil(abs(d) / step_rad)))
    return [(np.asarray(xy, float), yaw_from + d * k / n) for k in range(n + 1)]


def clearance_of(poses_xy_yaw: list, rocks_xy: np.ndarray, target_xy: np.ndarray, body: RoverBody) -> dict:
    """Minimum footprint distances (m) to the rock cells and to the target over ``[(xy (2,), yaw), ...]``.

    Returns ``{min_rock_m, min_target_m, worst_rock_xy}`` (inf when there are no rocks).
    """
    min_rock, worst = np.inf, None
    min_tgt = np.inf
    R = np.asarray(rocks_xy, float).reshape(-1, 2)
    T = np.asarray(target_xy, float).reshape(2)
    for xy, yaw in poses_xy_yaw:
        c, s = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, s], [-s, c]])  # site -> rover (2-D)
        if len(R):
            # only cells that can matter (within 2 m)
            near = np.abs(R - xy).max(axis=1) < 2.0
            if np.any(near):
                loc = (R[near] - xy) @ rot.T
                d = body.distance(loc)
                k = int(np.argmin(d))
                if d[k] < min_rock:
                    min_rock, worst = float(d[k]), R[near][k].tolist()
        dt = float(body.distance(((T - xy) @ rot.T)[None])[0])
        min_tgt = min(min_tgt, dt)
    return {"min_rock_m": float(min_rock), "min_target_m": float(min_tgt), "worst_rock_xy": worst}


def plan_approach(start: RoverPose, target_site_m, terrain: Optional[Terrain], rover_config: RoverConfig,
                  params: Optional[ApproachParams] = None, designation_camera: str = "pancam") -> ApproachPlan:
    """Plan the stops from ``start`` to the final pose in front of ``target_site_m`` (3,) (site frame).

    Tries the direct approach bearing, then the detour bearings in order, and
    keeps the first whose swept footprint clears the rocks (``rock_keep_out_m``)
    and the target (``target_keep_out_m``); if none does, the direct plan is
    returned with its (failing) clearance figures. Without a ``terrain`` the
    ground is taken as the start pose's plane and no rocks are known.
    """
    p = params or ApproachParams()
    T = np.asarray(target_site_m, float).reshape(3)
    S = start.T_site_rover.t[:2]
    d_start = float(np.linalg.norm(T[:2] - S))
    direct = math.atan2(T[1] - S[1], T[0] - S[0])
    rocks = (terrain.rock_cells(p.rock_cell_m, p.ground_window_m, p.rock_height_m)
             if terrain is not None else np.zeros((0, 2)))
    candidates = []
    for db in p.detour_bearings_rad:
        if d_start <= p.pancam_handoff_m and abs(db) > 1e-9:
            continue  # too close for a detour leg
        plan = _plan_bearing(start, T, terrain, rover_config, p, direct + db, db, rocks, designation_camera)
        candidates.append(plan)
        if not plan.clearance["blocked"]:
            return plan
    return candidates[0]


def _plan_bearing(start, T, terrain, rover_config, p, bearing, detour, rocks, designation_camera) -> ApproachPlan:
    S = start.T_site_rover.t[:2].copy()
    u = np.array([math.cos(bearing), math.sin(bearing)])
    d_start = float(np.linalg.norm(T[:2] - S))
    d_final = p.final_distance_m
    F = T[:2] - d_final * u
    if abs(detour) < 1e-9:
        poly = np.array([S, F])
    else:
        d_w = min(p.pancam_handoff_m, 0.8 * d_start)
        W = T[:2] - d_w * u
        poly = np.array([S, W, F])
    dists = stop_distances(d_start, p, designation_camera)
    start_plane = _plane_of(start.T_site_rover)
    stops = [PlannedStop(0, "start", d_start, start.T_site_rover, yaw_of(start.T_site_rover), 0.0, 0.0,
                         tilt_rad=tilt_of(start.T_site_rover))]
    s_prev = 0.0
    prev_xy, prev_yaw = S, yaw_of(start.T_site_rover)
    turn_poses = []
    path_pts = [S]
    for k, (dist, kind) in enumerate(dists, start=1):
        if kind == "final":
            pt, s, seg = F, _polyline_length(poly), len(poly) - 2
        else:
            r = _point_on_polyline_at_distance(poly, T[:2], dist, s_prev)
            if r is None:
                continue
            pt, s, seg = r
        seg_yaw = math.atan2(poly[seg + 1][1] - poly[seg][1], poly[seg + 1][0] - poly[seg][0])
        facing = math.atan2(T[1] - pt[1], T[0] - pt[0])
        heading = facing if kind in ("navcam-hazcam-handoff", "hazcam", "final") else seg_yaw
        # path from the previous stop: vertices of the polyline between s_prev and s
        seg_path = [prev_xy] + [poly[i] for i in range(1, len(poly) - 1) if s_prev < _arc(poly, i) < s] + [pt]
        for a, b in zip(seg_path[:-1], seg_path[1:]):
            turn_poses.extend(_turn_samples(a, prev_yaw, math.atan2(b[1] - a[1], b[0] - a[0]), p.turn_step_rad))
            prev_yaw = math.atan2(b[1] - a[1], b[0] - a[0])
        turn = float(_wrap(heading - prev_yaw))
        if abs(turn) > 1e-9:
            turn_poses.extend(_turn_samples(pt, prev_yaw, heading, p.turn_step_rad))
        guess = pose_on_plane(pt, heading, start_plane)
        plane, known = start_plane, False
        if terrain is not None:
            pl, _, _ = terrain.ground_plane(guess, p.body, p.rock_cell_m)
            if pl is not None:
                plane, known = pl, True
        Tsr = pose_on_plane(pt, heading, plane)
        stops.append(PlannedStop(k, kind, float(np.linalg.norm(T[:2] - pt)), Tsr, heading, float(s - s_prev), turn,
                                 tilt_rad=tilt_of(Tsr), terrain_known=known,
                                 path_from_previous=[np.asarray(q, float).tolist() for q in seg_path]))
        path_pts.extend(seg_path[1:])
        s_prev, prev_xy, prev_yaw = s, pt, heading
    for i, st in enumerate(stops):
        st.index = i
    path_xy = np.array(path_pts).reshape(-1, 2)
    pts, yaws = _sample_path_poses(path_xy, p.path_step_m)
    swept = [(pts[i], yaws[i]) for i in range(len(pts))] + turn_poses + [(stops[-1].T_site_rover.t[:2], stops[-1].heading_rad)]
    cl = clearance_of(swept, rocks, T[:2], p.body)
    cl["blocked"] = bool(cl["min_rock_m"] < p.rock_keep_out_m or cl["min_target_m"] < p.target_keep_out_m)
    cl["terrain_known_fraction"] = terrain.known_fraction_along(pts) if terrain is not None else 0.0
    cl["rock_cells"] = int(len(rocks))
    plan = ApproachPlan(T, start, float(bearing), float(detour), stops, path_xy, _polyline_length(path_xy), cl, p,
                        designation_camera)
    for st in plan.stops[1:]:
        st.cameras = [_shot(rover_config, st, c, T) for c in _cameras_for(st.kind)]
    return plan


def _arc(poly, i):
    return float(sum(np.linalg.norm(poly[j + 1] - poly[j]) for j in range(i)))


def _polyline_length(poly) -> float:
    poly = np.asarray(poly, float)
    return float(np.sum(np.linalg.norm(np.diff(poly, axis=0), axis=1))) if len(poly) > 1 else 0.0


def _plane_of(T_site_rover: RigidTransform):
    """The plane (a, b, c) through the rover origin perpendicular to its z axis."""
    n = T_site_rover.R[:, 2]
    p0 = T_site_rover.t
    # n . (X - p0) = 0 -> z = p0z - (nx (x - p0x) + ny (y - p0y)) / nz
    a, b = -n[0] / n[2], -n[1] / n[2]
    return a, b, p0[2] - a * p0[0] - b * p0[1]


def camera_model_at(rover_config: RoverConfig, camera: str, eye: str, pan_rad, tilt_rad,
                    T_site_rover: RigidTransform) -> CameraModel:
    """A camera's model in the SITE frame for a rover pose and joint angles (body cameras ignore the angles)."""
    return rover_config.camera_model(camera, eye, pan_rad or 0.0, tilt_rad or 0.0).transformed(T_site_rover)


def _shot(rover_config: RoverConfig, stop: PlannedStop, camera: str, target_site) -> CameraShot:
    Xr = stop.T_site_rover.inverse().apply(np.asarray(target_site, float))
    cam = rover_config.cameras.get(camera)
    if cam is None:
        return CameraShot(camera, None, None, None, None, False, note=f"no {camera} in the rover configuration")
    spec = cam.left
    pan = tilt = None
    note = ""
    if cam.mount == "mast":
        try:
            pan, tilt = rover_config.point_at(camera, Xr)
        except ValueError as e:
            return CameraShot(camera, None, None, None, None, False, note=f"cannot point: {e}")
    m = rover_config.camera_model(camera, "left", pan or 0.0, tilt or 0.0)
    uv = m.project(Xr[None])[0]
    rng = float(np.linalg.norm(Xr - m.C))
    margin = FOV_MARGIN_PX.get(camera, 20)
    ok = bool(np.all(np.isfinite(uv)) and margin <= uv[0] <= spec.width - 1 - margin
              and margin <= uv[1] <= spec.height - 1 - margin)
    return CameraShot(camera, pan, tilt, uv.tolist() if np.all(np.isfinite(uv)) else None, rng, ok,
                      template_half_px=TEMPLATE_HALF_PX.get(camera, 15),
                      search_radius_px=float(SEARCH_RADIUS_PX.get(camera, 60.0)), note=note)


# ============================================================================ nominal view checks
def check_views(plan: ApproachPlan, terrain: Terrain, rover_config: RoverConfig, surface_point_site,
                params: PredictParams, render: bool = True) -> dict:
    """Fill each stop's shots with occlusion, incidence, texture and coverage figures; render nominal views.

    ``surface_point_site`` (3,): the target's point on the terrain surface.
    Returns ``{(stop index, camera): RenderedView}`` of reduced-size views
    (``render_width_px`` wide) when ``render``.
    """
    X = np.asarray(surface_point_site, float)
    views = {}
    for st in plan.stops[1:]:
        for sh in st.cameras:
            if sh.uv is None:
                continue
            m_full = camera_model_at(rover_config, sh.camera, "left", sh.pan_rad, sh.tilt_rad, st.T_site_rover)
            C = m_full.C
            sh.occluded = bool(terrain.occluded(C[None], X[None], params.occlusion_tol_m)[0])
            ray = (X - C) / np.linalg.norm(X - C)
            hit = terrain.cast(C[None], ray[None])
            if hit.hit[0]:
                n = hit.normals[0]
                sh.incidence_rad = float(math.acos(min(1.0, abs(float(np.dot(n, ray))))))
            # texture and coverage of the window the tracker will use
            k = sh.template_half_px
            c = np.round(np.asarray(sh.uv))
            win = terrain.render(m_full, 0, 0, roi=(int(c[0] - k), int(c[1] - k), 2 * k + 1, 2 * k + 1))
            vals = win.image[np.isfinite(win.image)]
            sh.coverage = win.coverage
            sh.texture_std = float(vals.std()) if vals.size > 8 else 0.0
            if render:
                spec = rover_config.spec(sh.camera, "left")
                s = params.render_width_px / spec.width
                ms = scaled_model(m_full, s)
                views[(st.index, sh.camera)] = terrain.render(ms, int(round(spec.width * s)), int(round(spec.height * s)))
    return views


# ============================================================================ Monte Carlo
@dataclass
class McView:
    stop: int
    camera: str
    p_in_fov: float
    p_in_search: float
    p_visible: float  # not occluded
    p_ok: float  # all three
    p_chain: float  # this and every earlier view ok
    offset_px_rms: float  # rms distance predicted -> true pixel

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class McResult:
    n_samples: int
    sigma_position_m: float
    sigma_yaw_rad: float
    views: list  # McView
    p_arm_workspace: float
    p_success_geometry: float  # every view ok and the target in the arm workspace
    samples_ok: np.ndarray = field(repr=False, default=None)  # (n,) bool
    errors: dict = field(repr=False, default_factory=dict)  # per stop: (dxy (n, 2), dyaw (n,))

    def to_dict(self) -> dict:
        return {"n_samples": self.n_samples, "sigma_position_m": self.sigma_position_m,
                "sigma_yaw_rad": self.sigma_yaw_rad, "views": [v.to_dict() for v in self.views],
                "p_arm_workspace": self.p_arm_workspace, "p_success_geometry": self.p_success_geometry}


def _stereo_sigma_range(rover_config: RoverConfig, camera: str, range_m: float, sigma_d_px: float) -> float:
    cam = rover_config.cameras[camera]
    b = float(np.linalg.norm(cam.right.model.C - cam.left.model.C))
    f = cam.left.model.hs
    if b <= 0:
        return 0.0
    return float(range_m * range_m * sigma_d_px / (f * b))


def sample_pose_errors(plan: ApproachPlan, up: UncertaintyParams, sigma_position_m: float, sigma_yaw_rad: float,
                       rng: np.random.Generator, n: int) -> dict:
    """Per stop index: ``(dxy (n, 2), dyaw (n,))`` rover-frame error of the true pose w.r.t. the believed pose.

    A random walk: each leg adds ``N(0, sigma_leg^2)`` per axis with
    ``sigma_leg^2 = sigma_position_m^2 + (drive_error_frac * leg)^2`` and a yaw
    step with ``sigma^2 = sigma_yaw_rad^2 + (yaw_error_rad_per_m * leg)^2``.
    Stop 0 (today) has no error: the plan is made in today's estimated frame.
    """
    out = {0: (np.zeros((n, 2)), np.zeros(n))}
    dxy = np.zeros((n, 2))
    dyaw = np.zeros(n)
    for st in plan.stops[1:]:
        sp = math.hypot(sigma_position_m, up.drive_error_frac * st.leg_m)
        sy = math.hypot(sigma_yaw_rad, up.yaw_error_rad_per_m * st.leg_m)
        # the increment is expressed in the rover frame of the previous stop: rotate by the accumulated yaw
        inc = rng.standard_normal((n, 2)) * sp
        c, s = np.cos(dyaw), np.sin(dyaw)
        dxy = dxy + np.stack([c * inc[:, 0] - s * inc[:, 1], s * inc[:, 0] + c * inc[:, 1]], axis=1)
        dyaw = dyaw + rng.standard_normal(n) * sy
        out[st.index] = (dxy.copy(), dyaw.copy())
    return out


def _true_pose_arrays(T_believed: RigidTransform, dxy, dyaw):
    """R (n, 3, 3), t (n, 3) of ``T_believed @ Exp(dxy, dyaw)``."""
    n = len(dyaw)
    c, s = np.cos(dyaw), np.sin(dyaw)
    Rz = np.zeros((n, 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = c, -s, s, c, 1.0
    R = T_believed.R[None] @ Rz
    t = T_believed.t[None] + np.c_[dxy, np.zeros(n)] @ T_believed.R.T
    return R, t


def monte_carlo(plan: ApproachPlan, terrain: Optional[Terrain], rover_config: RoverConfig, target_true_site,
                up: UncertaintyParams, sigma_position_m: float, sigma_yaw_rad: float,
                designation_range_sigma_m: float = 0.0, occlusion_tol_m: float = 0.04) -> McResult:
    """Monte Carlo over the pose-estimate error (see :func:`sample_pose_errors`).

    Per sample and stop: the rover believes it is at the planned pose; it
    points each camera at its current target estimate (the previous stop's
    stereo re-estimate, carried through the believed poses); the true target
    ``target_true_site`` (3,) lands at ``uv_true``; the estimate at
    ``uv_pred``. Pointing is the nominal one plus the re-pointing shift
    ``uv_pred - uv_nominal`` (first order in the small pointing change).
    A view is ok when the re-pointed true pixel is inside the image (margin
    ``FOV_MARGIN_PX``), within the tracker's search radius of ``uv_pred``
    (square region), and the line of sight is not occluded by the terrain.
    At the final pose the rover drives so that its estimate sits at the
    workspace centre; the true target must be inside the arm workspace.
    """
    n = int(up.n_samples)
    rng = np.random.default_rng(up.seed)
    X_T = np.asarray(target_true_site, float).reshape(3)
    errors = sample_pose_errors(plan, up, sigma_position_m, sigma_yaw_rad, rng, n)
    # designation error along today's line of sight
    start = plan.start.T_site_rover
    C0 = start.apply(rover_config.camera_model(plan.designation_camera, "left").C) if plan.designation_camera in rover_config.cameras else start.t
    los = (X_T - C0) / np.linalg.norm(X_T - C0)
    X_est = X_T[None] + rng.standard_normal(n)[:, None] * designation_range_sigma_m * los[None]  # believed site frame
    ok_all = np.ones(n, bool)
    views = []
    for st in plan.stops[1:]:
        dxy, dyaw = errors[st.index]
        R_true, t_true = _true_pose_arrays(st.T_site_rover, dxy, dyaw)
        Tinv_b = st.T_site_rover.inverse()
        X_true_rover = np.einsum("nji,nj->ni", R_true, X_T[None] - t_true)  # R^T (X - t)
        last_est = None
        for sh in st.cameras:
            if sh.uv is None:
                views.append(McView(st.index, sh.camera, 0.0, 0.0, 0.0, 0.0, 0.0, float("nan")))
                ok_all[:] = False
                continue
            spec = rover_config.spec(sh.camera, "left")
            m = rover_config.camera_model(sh.camera, "left", sh.pan_rad or 0.0, sh.tilt_rad or 0.0)
            uv_pred = m.project(Tinv_b.apply(X_est))
            uv_true = m.project(X_true_rover)
            uv_nom = np.asarray(sh.uv, float)
            shift = uv_pred - uv_nom
            rep = uv_true - shift
            margin = FOV_MARGIN_PX.get(sh.camera, 20)
            fin = np.all(np.isfinite(rep), axis=1) & np.all(np.isfinite(uv_pred), axis=1)
            with np.errstate(invalid="ignore"):
                in_fov = fin & (rep[:, 0] >= margin) & (rep[:, 0] <= spec.width - 1 - margin) & \
                    (rep[:, 1] >= margin) & (rep[:, 1] <= spec.height - 1 - margin)
                off = np.abs(uv_true - uv_pred).max(axis=1)
                in_search = fin & (off <= sh.search_radius_px)
            C_true = np.einsum("nij,j->ni", R_true, m.C) + t_true
            if terrain is not None:
                vis = ~terrain.occluded(C_true, np.broadcast_to(X_T, C_true.shape), occlusion_tol_m)
            else:
                vis = np.ones(n, bool)
            ok = in_fov & in_search & vis
            ok_all &= ok
            with np.errstate(invalid="ignore"):
                rms = float(np.sqrt(np.nanmean(np.sum((uv_true - uv_pred) ** 2, axis=1))))
            views.append(McView(st.index, sh.camera, float(in_fov.mean()), float(in_search.mean()), float(vis.mean()),
                                float(ok.mean()), float(ok_all.mean()), rms))
            # stereo re-estimate from this camera: truth + range noise along its line of sight, into the believed frame
            sig_r = _stereo_sigma_range(rover_config, sh.camera, float(sh.range_m or 0.0), up.disparity_sigma_px)
            los_t = X_T[None] - C_true
            los_t /= np.linalg.norm(los_t, axis=1, keepdims=True)
            X_meas_true = X_T[None] + rng.standard_normal(n)[:, None] * sig_r * los_t
            X_meas_rover = np.einsum("nji,nj->ni", R_true, X_meas_true - t_true)
            last_est = st.T_site_rover.apply(X_meas_rover)
        if last_est is not None:
            X_est = last_est
    # final pose: the rover puts its estimate at the workspace centre; truth relative to the true final pose
    fin_st = plan.stops[-1]
    dxy, dyaw = errors[fin_st.index]
    R_true, t_true = _true_pose_arrays(fin_st.T_site_rover, dxy, dyaw)
    # the believed final pose is shifted so that the estimate lands where the truth was planned
    est_rover = fin_st.T_site_rover.inverse().apply(X_est)
    planned_rover = fin_st.T_site_rover.inverse().apply(X_T)
    corr = est_rover - planned_rover[None]  # the rover moves by this (its own frame) to centre the estimate
    t_true = t_true + corr @ fin_st.T_site_rover.R.T
    X_final = np.einsum("nji,nj->ni", R_true, X_T[None] - t_true)
    in_arm = plan.params.arm.contains(X_final[:, :2])
    p_arm = float(in_arm.mean())
    ok_all &= in_arm
    return McResult(n, float(sigma_position_m), float(sigma_yaw_rad), views, p_arm, float(ok_all.mean()),
                    ok_all, errors)


# ============================================================================ chain simulation on rendered views
@dataclass
class ChainSample:
    sample: int  # -1: nominal (no pose error)
    steps: list  # dicts: stop, camera, kind, ok (accurate), kept (not lost), error_px, error_m, ncc, reason
    ok: bool  # the target was kept to the final stop
    final_error_m: Optional[float] = None

    def to_dict(self) -> dict:
        return {"sample": self.sample, "ok": self.ok, "final_error_m": self.final_error_m, "steps": self.steps}


@dataclass
class ChainResult:
    samples: list  # ChainSample
    per_view: list  # dicts: stop, camera, kind, p_success, mean_error_px, n

    def to_dict(self) -> dict:
        return {"samples": [s.to_dict() for s in self.samples], "per_view": self.per_view}


def _crop_render(terrain: Terrain, m_site: CameraModel, centre_uv, half: int):
    c = np.round(np.asarray(centre_uv, float)).astype(int)
    return terrain.render(m_site, 0, 0, roi=(int(c[0] - half), int(c[1] - half), 2 * half + 1, 2 * half + 1))


def _fill(img: np.ndarray) -> np.ndarray:
    out = np.array(img, np.float32, copy=True)
    bad = ~np.isfinite(out)
    if bad.all():
        return np.zeros_like(out)
    out[bad] = float(np.nanmean(out))
    return out


def simulate_chain(plan: ApproachPlan, terrain: Terrain, rover_config: RoverConfig, designation_img: np.ndarray,
                   designation_model_site: CameraModel, designation_uv, surface_point_site, mc: Optional[McResult],
                   params: PredictParams, n_samples: Optional[int] = None) -> ChainResult:
    """Run the tracking chain and the handoffs on rendered views, nominal and for ``n_samples`` MC samples.

    The first window comes from today's real image (``designation_img``, its
    model in the site frame, the designated pixel). At each stop and camera the
    view is rendered at the sample's true pose with the pointing computed
    from the rover's estimate (exact ``point_at``), the previous window is
    scaled by the range / IFOV ratio and NCC-tracked around the predicted
    pixel; the search region rendered is the part that holds the true target
    plus ``search_margin_px`` (clipped to the chain's search radius). The
    navcam->hazcam handoff takes the tracked navcam pixel to 3-D on the
    terrain, projects it into the hazcam, and refines it by tracking an
    expected window draped from the navcam view. A step succeeds when the
    tracked pixel lies within ``SUCCESS_PX`` of the projection of the target's
    surface point; a failed step loses the target for the rest of the chain.
    """
    from ..core.tracking import track
    from ..core.windows import extract_window, scale_window, window_scale_for_handoff

    Xs = np.asarray(surface_point_site, float).reshape(3)
    n_mc = 0 if mc is None else min(int(n_samples if n_samples is not None else params.uncertainty.n_track_samples),
                                    mc.n_samples)
    sample_ids = [-1] + list(range(n_mc))
    samples = []
    for sid in sample_ids:
        prev = {"img": np.asarray(designation_img, np.float32), "origin": (0, 0), "uv": np.asarray(designation_uv, float),
                "model": designation_model_site, "range": float(np.linalg.norm(Xs - designation_model_site.C))}
        X_est = Xs.copy()
        steps, lost = [], False
        nav_view = None
        for st in plan.stops[1:]:
            if sid < 0:
                T_true = st.T_site_rover
            else:
                dxy, dyaw = mc.errors[st.index]
                T_true = perturb_pose(st.T_site_rover, dxy[sid:sid + 1], dyaw[sid:sid + 1])[0]
            for sh in st.cameras:
                kind = "track"
                if st.kind == "pancam-navcam-handoff" and sh.camera == "navcam":
                    kind = "handoff pancam->navcam"
                if st.kind == "navcam-hazcam-handoff" and sh.camera == "hazcam":
                    kind = "handoff navcam->hazcam"
                rec = {"stop": st.index, "camera": sh.camera, "kind": kind, "ok": False, "kept": False, "error_px": None,
                       "error_m": None, "ncc": None, "reason": ""}
                steps.append(rec)
                if lost:
                    rec["reason"] = "target lost earlier"
                    continue
                if sh.uv is None:
                    rec["reason"] = sh.note or "target not in view"
                    lost = True
                    continue
                spec = rover_config.spec(sh.camera, "left")
                Xr_est = st.T_site_rover.inverse().apply(X_est)
                pan = tilt = None
                if rover_config.cameras[sh.camera].mount == "mast":
                    try:
                        pan, tilt = rover_config.point_at(sh.camera, Xr_est)
                    except ValueError:
                        rec["reason"] = "cannot point"
                        lost = True
                        continue
                m_bel = rover_config.camera_model(sh.camera, "left", pan or 0.0, tilt or 0.0)
                uv_pred = m_bel.project(Xr_est[None])[0]
                m_true = m_bel.transformed(T_true)  # site frame, true pose
                uv_true = m_true.project(Xs[None])[0]
                if not (np.all(np.isfinite(uv_true)) and np.all(np.isfinite(uv_pred))):
                    rec["reason"] = "target behind the camera"
                    lost = True
                    continue
                margin = FOV_MARGIN_PX.get(sh.camera, 20)
                if not (margin <= uv_true[0] <= spec.width - 1 - margin and margin <= uv_true[1] <= spec.height - 1 - margin):
                    rec["reason"] = "out of the field of view"
                    lost = True
                    continue
                if terrain.occluded(m_true.C[None], Xs[None], params.occlusion_tol_m)[0]:
                    rec["reason"] = "occluded"
                    lost = True
                    continue
                if kind == "handoff navcam->hazcam" and nav_view is not None:
                    res = _hazcam_handoff(terrain, nav_view, m_true, uv_true, params)
                else:
                    rng_new = float(np.linalg.norm(Xr_est - m_bel.C))
                    radius = float(SEARCH_RADIUS_PX.get(sh.camera, 60.0))
                    res = _track_step(terrain, prev, m_true, uv_pred, uv_true, rng_new, radius,
                                      TEMPLATE_HALF_PX.get(sh.camera, 15), params,
                                      extract_window, scale_window, track, window_scale_for_handoff)
                uv_tr, ncc, reason, view = res
                rec["ncc"] = None if ncc is None or not np.isfinite(ncc) else float(ncc)
                if uv_tr is None:
                    rec["reason"] = reason
                    lost = True
                    continue
                err = float(np.hypot(*(uv_tr - uv_true)))
                rng_t = float(np.linalg.norm(Xs - m_true.C))
                tol = success_px(m_true, rng_t, sh.camera)
                rec["error_px"] = err
                rec["error_m"] = err * rng_t / m_true.hs
                rec["tolerance_px"] = tol
                rec["ok"] = err <= tol
                rec["kept"] = rec["error_m"] <= LOST_M
                if not rec["ok"]:
                    rec["reason"] = f"drift: tracked {100 * rec['error_m']:.1f} cm from the target ({err:.1f} px, tolerance {tol:.1f} px)"
                if not rec["kept"]:
                    rec["reason"] += ": lost"
                    lost = True
                    continue
                # stereo re-estimate: the terrain point at the tracked pixel, in the believed frame
                o, d = m_true.unproject(uv_tr[None])
                hit = terrain.cast(o, d)
                X_hit = hit.points[0] if hit.hit[0] else Xs
                X_est = st.T_site_rover.apply(T_true.inverse().apply(X_hit))
                prev = {"img": view.image, "origin": view.origin_uv, "uv": uv_tr, "model": m_true,
                        "range": float(np.linalg.norm(X_hit - m_true.C))}
                if sh.camera == "navcam":
                    nav_view = {"view": view, "uv": uv_tr, "model": m_true}
        kept = bool(steps) and not lost and steps[-1]["kept"]
        samples.append(ChainSample(sid, steps, kept, steps[-1]["error_m"] if kept else None))
    per_view = []
    if samples:
        for i, s0 in enumerate(samples[0].steps):
            vals = [s.steps[i] for s in samples if s.sample >= 0]
            errs = [v["error_m"] for v in vals if v["error_m"] is not None and v["kept"]]
            per_view.append({"stop": s0["stop"], "camera": s0["camera"], "kind": s0["kind"],
                             "nominal_ok": s0["ok"], "nominal_kept": s0["kept"], "nominal_error_px": s0["error_px"],
                             "nominal_error_m": s0["error_m"], "nominal_reason": s0["reason"],
                             "p_kept": (float(np.mean([v["kept"] for v in vals])) if vals else None),
                             "p_kept_given_visible": _p_given_visible(vals, "kept"),
                             "p_accurate_given_visible": _p_given_visible(vals, "ok"),
                             "mean_error_m": float(np.mean(errs)) if errs else None, "n": len(vals),
                             "reasons": sorted({v["reason"] for v in vals if v["reason"] and not v["ok"]})})
    return ChainResult(samples, per_view)


def success_px(model: CameraModel, range_m: float, camera: str) -> float:
    """Tracking tolerance (px) at ``range_m``: ``SUCCESS_M[camera]`` on the surface (at least ``MIN_SUCCESS_PX``)."""
    return float(max(MIN_SUCCESS_PX, SUCCESS_M.get(camera, 0.01) * model.hs / max(range_m, 1e-6)))


def _p_given_visible(vals, key):
    geo = ("out of the field of view", "occluded", "target behind the camera", "target lost earlier", "cannot point")
    vis = [v for v in vals if not (v["reason"] in geo)]
    return float(np.mean([v[key] for v in vis])) if vis else None


def _track_step(terrain, prev, m_true, uv_pred, uv_true, rng_new, radius, half, params,
                extract_window, scale_window, track, window_scale_for_handoff):
    """Track the previous window into a rendered crop. Returns (uv or None, ncc, reason, RenderedView)."""
    ifov_prev = 1.0 / prev["model"].hs
    ifov_new = 1.0 / m_true.hs
    scale = window_scale_for_handoff(ifov_prev, prev["range"], ifov_new, rng_new)
    src_half = max(3, int(math.ceil(half / scale)))
    pimg = _fill(prev["img"])
    puv = np.asarray(prev["uv"], float) - np.asarray(prev["origin"], float)
    win = extract_window(pimg, puv, src_half)
    tpl = scale_window(win, scale)
    off = float(np.abs(uv_true - uv_pred).max())
    r_eff = min(radius, off + params.search_margin_px)
    if off > radius:
        return None, None, "outside the search region", None
    # crop: the search region around the prediction plus the template, plus the window the next stop needs
    crop_half = int(math.ceil(r_eff + tpl.shape[0] // 2 + 2))
    need_next = int(math.ceil(3 * half + 4))  # a later camera change (scale ~1/3) needs ~3x the window
    crop_half = max(crop_half, int(math.ceil(off + need_next)))
    view = _crop_render(terrain, m_true, uv_pred, crop_half)
    img = _fill(view.image)
    if view.coverage < params.min_coverage * 0.5:
        return None, None, "no terrain data in the search region", view
    loc_pred = uv_pred - np.asarray(view.origin_uv, float)
    tr = track(tpl, img, loc_pred, r_eff, min_score=0.3)
    if not tr.ok or not np.all(np.isfinite(tr.uv)):
        return None, tr.score, f"track: {tr.reason}", view
    return tr.uv + np.asarray(view.origin_uv, float), tr.score, "", view


def _hazcam_handoff(terrain, nav, m_haz_true, uv_true, params):
    """Navcam->hazcam handoff on rendered views: kinematic point (terrain 3-D at the navcam pixel), refined by
    an expected hazcam window draped from the navcam view, NCC-tracked."""
    from ..core.expected import bilinear_sample
    from ..core.tracking import track

    o, d = nav["model"].unproject(np.asarray(nav["uv"], float)[None])
    hit = terrain.cast(o, d)
    if not hit.hit[0]:
        return None, None, "no terrain at the navcam pixel", None
    uv_k = m_haz_true.project(hit.points[0][None])[0]
    if not np.all(np.isfinite(uv_k)):
        return None, None, "target does not project into the hazcam", None
    k = HANDOFF_TEMPLATE_HALF_PX
    c = np.round(uv_k)
    # expected window: hazcam rays -> terrain -> navcam view intensities
    us, vs = np.meshgrid(np.arange(c[0] - k, c[0] + k + 1), np.arange(c[1] - k, c[1] + k + 1))
    uv = np.stack([us, vs], -1).reshape(-1, 2)
    oo, dd = m_haz_true.unproject(uv)
    hh = terrain.cast(oo, dd)
    nv = nav["view"]
    vals = np.full(len(uv), np.nan, np.float32)
    if np.any(hh.hit):
        puv = nav["model"].project(hh.points[hh.hit]) - np.asarray(nv.origin_uv, float)
        vals[hh.hit] = bilinear_sample(nv.image, puv)
    tpl = vals.reshape(2 * k + 1, 2 * k + 1)
    if np.isfinite(tpl).mean() < 0.5:
        return None, None, "expected hazcam window mostly empty", None
    tpl = _fill(tpl)
    off = float(np.abs(uv_true - uv_k).max())
    radius = HANDOFF_SEARCH_RADIUS_PX
    if off > radius:
        return None, None, "outside the search region", None
    r_eff = min(radius, off + params.search_margin_px)
    half = int(math.ceil(r_eff + k + 2))
    half = max(half, int(math.ceil(off + 3 * TEMPLATE_HALF_PX.get("hazcam", 15) + 4)))
    view = _crop_render(terrain, m_haz_true, uv_k, half)
    img = _fill(view.image)
    tc = uv_k - (c - k)
    tr = track(tpl, img, uv_k - np.asarray(view.origin_uv, float), r_eff, template_center_uv=tc, min_score=0.3)
    if not tr.ok or not np.all(np.isfinite(tr.uv)):
        return None, tr.score, f"track: {tr.reason}", view
    return tr.uv + np.asarray(view.origin_uv, float), tr.score, "", view


# ============================================================================ risks
@dataclass
class Risk:
    stop: int
    camera: str
    what: str  # "view" | "handoff pancam->navcam" | "handoff navcam->hazcam" | "arm"
    probability: Optional[float]
    reasons: list

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def assess_risks(plan: ApproachPlan, mc: Optional[McResult], chain: Optional[ChainResult],
                 params: PredictParams) -> list:
    """Stops and handoffs at risk, each with the reasons (occlusion, out of field of view, outside the
    search region, low texture, no terrain data, too oblique, tracking loses the target, drift, arm workspace;
    :func:`run_prediction` adds the foreshortening changes)."""
    risks = []
    mcv = {(v.stop, v.camera): v for v in (mc.views if mc else [])}
    chv = {(v["stop"], v["camera"]): v for v in (chain.per_view if chain else [])}
    for st in plan.stops[1:]:
        for sh in st.cameras:
            reasons = []
            key = (st.index, sh.camera)
            v = mcv.get(key)
            c = chv.get(key)
            what = c["kind"] if c is not None and c["kind"] != "track" else "view"
            if sh.uv is None:
                reasons.append(sh.note or "target not in view")
            else:
                if not sh.in_fov:
                    reasons.append("out of field of view (nominal)")
                if sh.occluded:
                    reasons.append("occlusion (nominal line of sight blocked)")
                if sh.coverage is not None and sh.coverage < params.min_coverage:
                    reasons.append(f"no terrain data around the target ({100 * sh.coverage:.0f}% of the window)")
                if sh.texture_std is not None and sh.texture_std < params.low_texture_std:
                    reasons.append(f"low texture (window std {sh.texture_std:.3f})")
                if sh.incidence_rad is not None and sh.incidence_rad > params.max_incidence_rad:
                    reasons.append(f"too oblique (incidence {math.degrees(sh.incidence_rad):.0f} deg)")
            if v is not None:
                if v.p_in_fov < params.risk_probability and sh.in_fov:
                    reasons.append(f"out of field of view (P in view {v.p_in_fov:.2f})")
                if v.p_in_search < params.risk_probability:
                    reasons.append(f"outside the search region (P {v.p_in_search:.2f}, rms offset {v.offset_px_rms:.0f} px)")
                if v.p_visible < params.risk_probability:
                    reasons.append(f"occlusion (P visible {v.p_visible:.2f})")
            if c is not None:
                pk = c.get("p_kept_given_visible")
                geometric = ("target lost earlier", "out of the field of view", "occluded", "target behind the camera",
                             "cannot point", "target not in view")
                if not c["nominal_kept"] and c["nominal_reason"] not in geometric and c["nominal_reason"] != sh.note:
                    reasons.append(f"tracking loses the target on the nominal expected view ({c['nominal_reason']})")
                elif pk is not None and pk < params.risk_probability:
                    reasons.append(f"tracking loses the target on expected views (P kept {pk:.2f})")
                elif not c["nominal_ok"] and c["nominal_error_m"] is not None:
                    reasons.append(c["nominal_reason"])
            prob = None
            if v is not None:
                prob = v.p_ok
                if c is not None and c.get("p_kept_given_visible") is not None:
                    prob = prob * c["p_kept_given_visible"]
            if reasons:
                risks.append(Risk(st.index, sh.camera, what, prob, reasons))
    if mc is not None and mc.p_arm_workspace < params.risk_probability:
        risks.append(Risk(plan.stops[-1].index, "arm", "arm", mc.p_arm_workspace,
                          [f"target may fall outside the arm workspace (P inside {mc.p_arm_workspace:.2f})"]))
    return risks


def foreshortening_changes(plan: ApproachPlan) -> dict:
    """``cos(incidence)`` ratio of each view to the previous view of the chain: ``{(stop, camera): ratio}``.

    A planar target's apparent aspect scales with ``cos(incidence)``; the chain
    rescales windows isotropically (range / IFOV), so a ratio far from 1 is an
    anisotropic change NCC has to absorb.
    """
    out = {}
    prev = None
    for st in plan.stops[1:]:
        for sh in st.cameras:
            if sh.uv is None or sh.incidence_rad is None:
                continue
            c = max(math.cos(sh.incidence_rad), 1e-3)
            if prev is not None:
                out[(st.index, sh.camera)] = c / prev
            prev = c
    return out


# ============================================================================ the whole prediction
@dataclass
class Prediction:
    target_id: str
    plan: ApproachPlan
    mc: Optional[McResult]
    chain: Optional[ChainResult]
    risks: list
    views: dict  # (stop, camera) -> RenderedView (reduced size)
    surface_point_site: np.ndarray
    confidence: float  # P(success): geometry MC x tracking on expected views (given visible)
    sigma_source: str
    notes: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)
    accuracy: dict = field(default_factory=dict)  # predicted final placement error (m): nominal, mean, max over kept samples
    terrain: Optional[Terrain] = field(default=None, repr=False)  # today's terrain the views were rendered from

    def to_dict(self) -> dict:
        return {
            "target": self.target_id, "plan": self.plan.to_dict(), "accuracy": self.accuracy,
            "monte_carlo": None if self.mc is None else self.mc.to_dict(),
            "chain": None if self.chain is None else self.chain.to_dict(),
            "risks": [r.to_dict() for r in self.risks], "confidence": self.confidence,
            "surface_point_site_m": self.surface_point_site.tolist(), "sigma_source": self.sigma_source,
            "notes": self.notes, "seconds": self.seconds,
        }


def confidence_of(mc: Optional[McResult], chain: Optional[ChainResult]) -> float:
    """Predicted P(success) = P(geometry ok: every view in field, in search, visible; arm reaches) from the Monte
    Carlo, times the fraction of the rendered chain samples that were geometrically ok and tracked the target
    to the end within tolerance (the nominal chain when no sample was geometrically ok)."""
    p = 1.0 if mc is None else mc.p_success_geometry
    if chain is None:
        return float(p)
    runs = [s for s in chain.samples if s.sample >= 0]
    if mc is not None and mc.samples_ok is not None:
        runs = [s for s in runs if mc.samples_ok[s.sample]]
    if not runs:
        runs = [s for s in chain.samples if s.sample < 0]
    frac = float(np.mean([s.ok for s in runs])) if runs else 1.0
    return float(p * frac)


def run_prediction(target_id: str, plan: ApproachPlan, terrain: Terrain, rover_config: RoverConfig,
                   designation_img, designation_model_site: CameraModel, designation_uv, target_site_m,
                   sigma_position_m: float, sigma_yaw_rad: float, sigma_source: str,
                   designation_range_sigma_m: float = 0.0, params: Optional[PredictParams] = None) -> Prediction:
    """Views, Monte Carlo, chain simulation and risks for a planned approach (pure: arrays in, results out)."""
    import time

    params = params or PredictParams()
    notes, secs = [], {}
    X_T = np.asarray(target_site_m, float)
    # the target's point on the terrain surface: today's designation ray cast into the mesh
    o, d = designation_model_site.unproject(np.asarray(designation_uv, float)[None])
    Xs = terrain.surface_point(o[0], d[0])
    if Xs is None or np.linalg.norm(Xs - X_T) > max(0.1, 0.05 * np.linalg.norm(X_T - o[0])):
        notes.append("the designation ray misses today's stereo surface near the target; using the designated point")
        Xs = X_T
    t0 = time.perf_counter()
    views = check_views(plan, terrain, rover_config, Xs, params)
    secs["views"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    mc = monte_carlo(plan, terrain, rover_config, Xs, params.uncertainty, sigma_position_m, sigma_yaw_rad,
                     designation_range_sigma_m, params.occlusion_tol_m)
    secs["monte_carlo"] = time.perf_counter() - t0
    chain = None
    if params.run_chain:
        t0 = time.perf_counter()
        chain = simulate_chain(plan, terrain, rover_config, designation_img, designation_model_site, designation_uv,
                               Xs, mc, params)
        secs["chain"] = time.perf_counter() - t0
    risks = assess_risks(plan, mc, chain, params)
    for (si, cam), ratio in sorted(foreshortening_changes(plan).items()):
        if not (1.0 / params.max_foreshortening_change <= ratio <= params.max_foreshortening_change):
            msg = f"too oblique a change of view: the target's foreshortening changes x{ratio:.2f} from the previous image"
            r = next((r for r in risks if r.stop == si and r.camera == cam), None)
            if r is None:
                risks.append(Risk(si, cam, "view", None, [msg]))
            else:
                r.reasons.append(msg)
    risks.sort(key=lambda r: (r.stop, r.camera))
    conf = confidence_of(mc, chain)
    acc = {}
    if chain is not None:
        nom = [s for s in chain.samples if s.sample < 0]
        kept = [s.final_error_m for s in chain.samples if s.sample >= 0 and s.ok and s.final_error_m is not None]
        acc = {"nominal_final_error_m": nom[0].final_error_m if nom else None,
               "mean_final_error_m": float(np.mean(kept)) if kept else None,
               "max_final_error_m": float(np.max(kept)) if kept else None, "samples_kept": len(kept),
               "goal_m": SUCCESS_M["hazcam"]}
    return Prediction(target_id, plan, mc, chain, risks, views, np.asarray(Xs, float), conf, sigma_source, notes, secs,
                      acc, terrain)


# ============================================================================ from a downlink
STEREO_CAMERAS = ("pancam", "navcam", "hazcam")
_PRIORITY = {"pancam": 0, "navcam": 1, "hazcam": 2}


def resolve_target(dl, target_id: str, targets_doc: Optional[dict], with_normal: bool = True) -> tuple:
    """The designation record for ``target_id``: from ``targets.json`` (``targets_doc``) if designated there,
    else designated on the fly from its mark in the first left pancam image (or navcam if there is no pancam).

    Returns ``(record, designated_now: bool)``. Raises ``InputError`` when the id is neither designated nor
    marked, or the mark is in no usable image.
    """
    from ..model import InputError

    for rec in (targets_doc or {}).get("targets", []) or []:
        if isinstance(rec, dict) and rec.get("id") == target_id:
            return rec, False
    known = sorted({r.get("id") for r in (targets_doc or {}).get("targets", []) or [] if isinstance(r, dict)} |
                   {t.id for t in dl.targets})
    marks = next((t for t in dl.targets if t.id == target_id), None)
    if marks is None:
        raise InputError(target_id, "--target", "not designated (targets.json) and not a marked target in the downlink"
                         + (f"; known: {', '.join(str(k) for k in known)}" if known else ""))
    from .designate import designate

    for cam in ("pancam", "navcam"):
        lefts = sorted((im for im in dl.images if im.camera == cam and im.eye == "left"), key=lambda i: i.time_s)
        for im in lefts:
            mk = marks.mark_in(im.product_id)
            if mk is not None and dl.stereo_pair(im) is not None:
                rec = designate(dl, im, [mk.u, mk.v], target_id=target_id, with_normal=with_normal)
                rec["designated_from"] = "mark"
                return rec, True
        if lefts:
            break
    raise InputError(target_id, "marks", "the target is marked in no left pancam/navcam image with a stereo pair")


def terrain_sources(dl, position, cameras=STEREO_CAMERAS, downsample: int = 2, target_range_m: Optional[float] = None):
    """Dense stereo of every left/right pair of ``cameras`` at ``position`` -> list of :class:`TerrainSource` (site frame)."""
    from ..core.dense_stereo import dense_stereo

    out = []
    for im in sorted(dl.images_at(position, eye="left"), key=lambda i: (_PRIORITY.get(i.camera, 9), i.time_s)):
        if im.camera not in cameras:
            continue
        right = dl.stereo_pair(im)
        if right is None or (right.width, right.height) != (im.width, im.height):
            continue
        if im.camera == "pancam":
            r = target_range_m or 10.0
            lo, hi = max(1.0, 0.3 * r), 2.5 * r + 5.0
        elif im.camera == "hazcam":
            lo, hi = 0.3, 6.0
        else:
            lo, hi = 0.8, 40.0
        L = im.pixels_float()
        ds = dense_stereo(L, right.pixels_float(), im.camera_model, right.camera_model,
                          min_range_m=lo, max_range_m=hi, downsample=downsample)
        T = im.pose.T_site_rover
        xyz = ds.xyz
        flat = xyz.reshape(-1, 3)
        ok = np.all(np.isfinite(flat), axis=1)
        xs = np.full_like(flat, np.nan)
        xs[ok] = T.apply(flat[ok])
        out.append(TerrainSource(im.product_id, im.camera, xs.reshape(xyz.shape), L, im.camera_model.transformed(T),
                                 T.apply(ds.rectified.left_model.C), _PRIORITY.get(im.camera, 9)))
    return out


def sigmas_for(product, params: UncertaintyParams) -> tuple:
    """(sigma_position_m, sigma_yaw_rad, source text): override, else the downlink pose's, else the defaults."""
    sp, sy = params.sigma_position_m, params.sigma_yaw_rad
    src = []
    if sp is None:
        sp = product.pose.sigma_position_m
        src.append("position: downlink" if sp is not None else "position: default")
        if sp is None:
            sp = params.default_sigma_position_m
    else:
        src.append("position: parameter")
    if sy is None:
        sy = product.pose.sigma_yaw_rad
        src.append("yaw: downlink" if sy is not None else "yaw: default")
        if sy is None:
            sy = params.default_sigma_yaw_rad
    else:
        src.append("yaw: parameter")
    return float(sp), float(sy), ", ".join(src)


@dataclass
class TargetContext:
    """What a prediction needs from the downlink for one target."""

    record: dict
    designated_now: bool
    product: object  # ImageProduct of the designation
    start: RoverPose
    target_site_m: np.ndarray


def target_context(dl, record: dict, designated_now: bool = False) -> TargetContext:
    from ..model import InputError

    if not record.get("ok", True) or record.get("xyz_site_m") is None:
        raise InputError(str(record.get("id")), "designation", f"the target has no 3-D position ({record.get('reason') or 'no stereo'})")
    prod = dl.product(record["product_id"])
    return TargetContext(record, designated_now, prod, prod.pose, np.asarray(record["xyz_site_m"], float))


def predict_target(dl, record: dict, params: Optional[PredictParams] = None, designated_now: bool = False,
                   terrain: Optional[Terrain] = None) -> Prediction:
    """Plan and predict tomorrow's approach to a designated target from today's downlink (the designation's position)."""
    import time

    params = params or PredictParams()
    ctx = target_context(dl, record, designated_now)
    t0 = time.perf_counter()
    if terrain is None:
        srcs = terrain_sources(dl, ctx.product.position, downsample=params.stereo_downsample,
                               target_range_m=record.get("range_m"))
        terrain = Terrain(srcs, params.max_edge_ratio, params.min_edge_m, params.smooth_sigma_px)
    t_terrain = time.perf_counter() - t0
    t0 = time.perf_counter()
    plan = plan_approach(ctx.start, ctx.target_site_m, terrain, dl.rover_config, params.approach,
                         designation_camera=ctx.product.camera)
    t_plan = time.perf_counter() - t0
    sp, sy, src = sigmas_for(ctx.product, params.uncertainty)
    pred = run_prediction(record["id"], plan, terrain, dl.rover_config, ctx.product.pixels_float(),
                          ctx.product.camera_model.transformed(ctx.start.T_site_rover), record["pixel_uv"],
                          ctx.target_site_m, sp, sy, src, float(record.get("range_sigma_m") or 0.0), params)
    pred.seconds.update({"terrain": t_terrain, "plan": t_plan})
    return pred
