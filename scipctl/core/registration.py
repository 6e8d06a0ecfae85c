"""Point-cloud registration for mesh-registration handoff (Open3D ICP, imported lazily)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from .transforms import RigidTransform


@dataclass
class RegistrationResult:
    T_target_source: RigidTransform  # maps source-cloud points onto the target cloud
    fitness: float  # fraction of source points with a correspondence (Open3D fitness) at the finest scale
    inlier_rmse_m: float
    n_source: int  # points used after cropping/downsampling
    n_target: int
    correction_rad: float  # rotation of the refinement relative to the seed
    correction_m: float  # translation of the refinement relative to the seed (at the crop centre)
    kept_seed: bool = False  # ICP did not fit the clouds better than the seed at the finest scale: the seed stands


def _to_o3d(points: np.ndarray):
    from .open3d_import import open3d

    o3d = open3d()

    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(np.ascontiguousarray(points, dtype=np.float64))
    return pc


def squared_distances(p: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Squared distances ``(N,)`` of points ``(N, 3)`` from ``c`` ``(3,)``."""
    # column by column: numpy reduces the short axis of an (N, 3) array several times slower
    out = (p[:, 0] - c[0]) ** 2
    out += (p[:, 1] - c[1]) ** 2
    out += (p[:, 2] - c[2]) ** 2
    return out


def _finite_rows(p: np.ndarray) -> np.ndarray:
    """``(N,)`` bool: rows of ``(N, 3)`` with three finite components (their sum is finite iff they are)."""
    return np.isfinite(p[:, 0] + p[:, 1] + p[:, 2])


def select_rows(p: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """``p[keep]`` for a boolean ``keep`` ``(N,)``, or ``p`` itself (no copy) when every row is kept."""
    return p if keep.all() else p[keep]


def _box(p: np.ndarray, margin: float) -> tuple:
    """Axis-aligned bounding box of points ``(N, 3)`` widened by ``margin`` on every side: ``(lo, hi)``."""
    lo = np.array([p[:, k].min() for k in range(3)]) - margin  # by column: see squared_distances
    hi = np.array([p[:, k].max() for k in range(3)]) + margin
    return lo, hi


def _in_box(p: np.ndarray, box: tuple) -> np.ndarray:
    """``(N,)`` bool: points ``(N, 3)`` inside ``box`` ``(lo, hi)`` (one column at a time: no (N, 3) temporaries)."""
    lo, hi = box
    ok = (p[:, 0] >= lo[0]) & (p[:, 0] <= hi[0])
    for k in (1, 2):
        ok &= (p[:, k] >= lo[k]) & (p[:, k] <= hi[k])
    return ok


@dataclass
class PreparedClouds:
    """The two clouds of :func:`register_clouds`, cropped and voxel-gridded once, so that ICP can be run from
    several seeds on the same points (:func:`icp_from`).

    ``grids[voxel] = (source, target)`` Open3D clouds: the source already moved by ``T_target_source_init``
    (the *seeded* frame: a transform ``M`` found on these grids maps the seeded source onto the target, i.e.
    ``T_target_source = M @ T_target_source_init``); ``target_m`` ``(M, 3)`` the cropped target points.
    """

    grids: dict
    T_target_source_init: RigidTransform
    target_m: np.ndarray
    scales_m: tuple
    max_corr_voxels: float
    crop_center_m: Optional[np.ndarray]
    noise_origin: Optional[np.ndarray]
    noise_k: Optional[float]

    @property
    def centre_m(self) -> np.ndarray:
        """``(3,)`` target frame: the crop centre, or the cropped target's mean."""
        return self.crop_center_m if self.crop_center_m is not None else self.target_m.mean(axis=0)

    def scale_clouds(self, voxel: float, M_target_seeded: np.ndarray):
        """The clouds ICP uses at the scale ``voxel`` after the alignment ``M_target_seeded`` ``(4, 4)``:
        ``(source, target, correspondence radius)`` (see :func:`register_clouds` for the two selections)."""
        s, t = self.grids[voxel]
        radius = voxel * self.max_corr_voxels
        if self.noise_k is not None:  # the target points precise enough for this scale's correspondences
            t_pts = np.asarray(t.points)
            near = np.flatnonzero(squared_distances(t_pts, self.noise_origin) <= radius / self.noise_k)
            if len(near) < len(t_pts):
                t = t.select_by_index(near)
        # source points that, moved by the alignment so far, lie beyond the target's box widened by twice this
        # scale's correspondence distance cannot pair up at this scale: leave them out (far navcam clouds reach
        # well beyond the hazcam's; the finest scale has most points)
        s_pts = np.asarray(s.points)
        keep = np.flatnonzero(_in_box(s_pts @ M_target_seeded[:3, :3].T + M_target_seeded[:3, 3],
                                      _box(np.asarray(t.points), 2.0 * radius)))
        if len(keep) < len(s_pts):
            s = s.select_by_index(keep)
        return s, t, radius


def prepare_clouds(
    source_m: np.ndarray,
    target_m: np.ndarray,
    T_target_source_init: RigidTransform,
    scales_m: tuple = (0.04, 0.02, 0.01),
    crop_center_m: Optional[np.ndarray] = None,
    crop_radius_m: Optional[float] = None,
    max_corr_voxels: float = 1.5,
    target_noise: Optional[tuple] = None,
) -> PreparedClouds:
    """Crop and grid the clouds as :func:`register_clouds` does (its arguments of the same names)."""
    from .open3d_import import open3d

    open3d()  # the grids are Open3D clouds

    noise_origin = noise_k = None
    if target_noise is not None:
        noise_origin = np.asarray(target_noise[0], dtype=float).reshape(3)
        noise_k = float(target_noise[1])
        if not (np.all(np.isfinite(noise_origin)) and np.isfinite(noise_k) and noise_k > 0):
            raise ValueError(f"target_noise: expected (finite origin (3,), k > 0), got {target_noise!r}")
    src = np.asarray(source_m, dtype=float)
    tgt = np.asarray(target_m, dtype=float)
    if src.ndim != 2 or src.shape[1] != 3 or tgt.ndim != 2 or tgt.shape[1] != 3:
        raise ValueError("source_m and target_m must be (N, 3)")
    # (selections copy only when they drop something: these clouds have up to a million points)
    src = select_rows(src, _finite_rows(src))
    tgt = select_rows(tgt, _finite_rows(tgt))
    src_in_tgt = T_target_source_init.apply(src)
    if crop_center_m is not None and crop_radius_m is not None:
        c = np.asarray(crop_center_m, float)
        r2 = float(crop_radius_m) ** 2
        src_in_tgt = select_rows(src_in_tgt, squared_distances(src_in_tgt, c) < r2)
        tgt = select_rows(tgt, squared_distances(tgt, c) < r2)
    # where the clouds can overlap: each within the other's bounding box, widened by twice the coarsest
    # correspondence distance (points farther out can never pair up; they only cost time)
    margin = 2.0 * max(scales_m) * max_corr_voxels
    if len(src_in_tgt) and len(tgt):
        box_t, box_s = _box(tgt, margin), _box(src_in_tgt, margin)
        src_in_tgt, tgt = select_rows(src_in_tgt, _in_box(src_in_tgt, box_t)), select_rows(tgt, _in_box(tgt, box_s))
    if len(src_in_tgt) < 50 or len(tgt) < 50:
        raise ValueError(f"too few points to register ({len(src_in_tgt)} source, {len(tgt)} target)")
    # voxel grids finest first, each coarser one from the finer (cheaper than from the full clouds)
    grids = {}
    ps, pt = _to_o3d(src_in_tgt), _to_o3d(tgt)
    for voxel in sorted(scales_m):
        ps, pt = ps.voxel_down_sample(voxel), pt.voxel_down_sample(voxel)
        grids[voxel] = (ps, pt)
    return PreparedClouds(grids, T_target_source_init, tgt, tuple(scales_m), float(max_corr_voxels),
                          None if crop_center_m is None else np.asarray(crop_center_m, float), noise_origin, noise_k)


@dataclass
class IcpRun:
    """ICP over some scales of a :class:`PreparedClouds`: ``M_target_seeded`` ``(4, 4)`` (seeded frame),
    Open3D's result at the last scale run (``reg``), and that scale's clouds and radius (None/0 when no scale had
    enough points)."""

    M_target_seeded: np.ndarray
    reg: object
    source: object
    target: object
    radius_m: float
    n_source: int
    n_target: int


def icp_from(prep: PreparedClouds, M_target_seeded_init: np.ndarray, scales_m: Optional[tuple] = None,
             method: str = "point-to-plane", max_iterations: int = 25) -> IcpRun:
    """Coarse-to-fine ICP on ``prep``'s grids from the alignment ``M_target_seeded_init`` ``(4, 4)`` (identity:
    the seed itself), over ``scales_m`` (default: all of ``prep``'s, in its order)."""
    from .open3d_import import open3d

    o3d = open3d()

    M_target_seeded = np.array(M_target_seeded_init, dtype=float)
    reg = s = t = None
    radius = 0.0
    n_s = n_t = 0
    for voxel in prep.scales_m if scales_m is None else scales_m:
        s, t, radius = prep.scale_clouds(voxel, M_target_seeded)
        n_s, n_t = len(s.points), len(t.points)
        if n_s < 20 or n_t < 20:
            continue
        crit = o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=max_iterations)
        if method == "generalized":
            for pc in (s, t):
                pc.estimate_covariances(o3d.geometry.KDTreeSearchParamHybrid(radius=2.5 * voxel, max_nn=30))
            est = o3d.pipelines.registration.TransformationEstimationForGeneralizedICP()
            reg = o3d.pipelines.registration.registration_generalized_icp(s, t, radius, M_target_seeded, est, crit)
        elif method == "point-to-plane":
            t.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2.5 * voxel, max_nn=30))
            est = o3d.pipelines.registration.TransformationEstimationPointToPlane()
            reg = o3d.pipelines.registration.registration_icp(s, t, radius, M_target_seeded, est, crit)
        else:
            raise ValueError(f"unknown registration method {method!r}")
        M_target_seeded = np.asarray(reg.transformation)
    return IcpRun(M_target_seeded, reg, s, t, radius, n_s, n_t)


def register_clouds(
    source_m: np.ndarray,
    target_m: np.ndarray,
    T_target_source_init: RigidTransform,
    method: str = "point-to-plane",
    scales_m: tuple = (0.04, 0.02, 0.01),
    crop_center_m: Optional[np.ndarray] = None,
    crop_radius_m: Optional[float] = None,
    max_iterations: int = 25,
    max_corr_voxels: float = 1.5,
    min_fitness_gain: float = 0.01,
    min_rmse_gain: float = 0.05,
    target_noise: Optional[tuple] = None,
    prepared: Optional[PreparedClouds] = None,
) -> RegistrationResult:
    """Align ``source_m`` ``(N, 3)`` to ``target_m`` ``(M, 3)`` starting from ``T_target_source_init`` (a first
    estimate of ``T_target_source``).

    Coarse-to-fine ICP over voxel sizes ``scales_m``; the correspondence
    distance at each scale is ``max_corr_voxels`` voxels (1.5: wider lets
    differently-sampled stereo surfaces pull the alignment off, measured on
    simulated sols in docs/handoff.md). ``method`` is ``point-to-plane`` or
    ``generalized`` (GICP). With ``crop_center_m``/``crop_radius_m`` (target
    frame) only points near the centre are used (both clouds, the source after
    applying ``T_target_source_init``). Points that cannot pair up are left out: each cloud
    outside the other's box widened by twice the coarsest correspondence
    distance, and at each scale the source points that, moved by the alignment
    so far, lie outside the target's box widened by twice that scale's
    distance (``fitness`` counts only the source points kept at the finest
    scale). The result replaces the seed only if, at the finest
    scale, it raises the fitness by ``min_fitness_gain`` or lowers the inlier
    RMS by the fraction ``min_rmse_gain`` (``kept_seed`` says which).

    ``target_noise`` ``(origin_m (3,), k_per_m)``: the target cloud's points
    are uncertain along their range by ``k r^2``, ``r`` their distance from
    ``origin_m`` (stereo: ``k = sigma_disparity / (f B)``). At each scale only
    the target points whose uncertainty is within that scale's correspondence
    distance ``d`` are used, ``r <= sqrt(d / k)``: a point farther from its
    surface than the correspondences reach pairs up with the wrong surface or
    not at all, adding error and time, not information. Coarse scales use the
    far points (their reach is long), the finest ones the near points.

    ``prepared``: the clouds already cropped and gridded by :func:`prepare_clouds` with these arguments and
    ``T_target_source_init`` (the clouds and crop arguments are then not used again).
    """
    from .open3d_import import open3d

    o3d = open3d()

    if prepared is None:
        prepared = prepare_clouds(source_m, target_m, T_target_source_init, scales_m, crop_center_m, crop_radius_m,
                                  max_corr_voxels, target_noise)
    run = icp_from(prepared, np.eye(4), method=method, max_iterations=max_iterations)
    if run.reg is None:
        raise ValueError("registration had too few points at every scale")
    reg, s, t, radius = run.reg, run.source, run.target, run.radius_m
    M_target_seeded = run.M_target_seeded
    # keep the seed unless ICP fits the clouds measurably better at the finest scale: on noisy stereo clouds
    # ICP otherwise drifts along weakly constrained directions from an already good seed
    seed_eval = o3d.pipelines.registration.evaluate_registration(s, t, radius, np.eye(4))
    kept_seed = not (reg.fitness > seed_eval.fitness + min_fitness_gain
                     or reg.inlier_rmse < (1.0 - min_rmse_gain) * seed_eval.inlier_rmse)
    if kept_seed:
        M_target_seeded, reg = np.eye(4), seed_eval
    T_target_seeded = RigidTransform.from_matrix(M_target_seeded)  # seeded: the source moved by T_target_source_init
    centre = prepared.centre_m
    return RegistrationResult(
        T_target_source=T_target_seeded @ prepared.T_target_source_init,
        fitness=float(reg.fitness),
        inlier_rmse_m=float(reg.inlier_rmse),
        n_source=run.n_source,
        n_target=run.n_target,
        correction_rad=T_target_seeded.rotation_angle_rad(),
        correction_m=float(np.linalg.norm(T_target_seeded.apply(centre) - centre)),
        kept_seed=kept_seed,
    )
