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
    import open3d as o3d

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
    """
    import open3d as o3d

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
    M_target_seeded = np.eye(4)
    reg = None
    n_s = n_t = 0
    for voxel in scales_m:
        s, t = grids[voxel]
        radius = voxel * max_corr_voxels
        if target_noise is not None:  # the target points precise enough for this scale's correspondences
            t_pts = np.asarray(t.points)
            near = np.flatnonzero(squared_distances(t_pts, noise_origin) <= radius / noise_k)
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
    if reg is None:
        raise ValueError("registration had too few points at every scale")
    # keep the seed unless ICP fits the clouds measurably better at the finest scale: on noisy stereo clouds
    # ICP otherwise drifts along weakly constrained directions from an already good seed
    seed_eval = o3d.pipelines.registration.evaluate_registration(s, t, radius, np.eye(4))
    kept_seed = not (reg.fitness > seed_eval.fitness + min_fitness_gain
                     or reg.inlier_rmse < (1.0 - min_rmse_gain) * seed_eval.inlier_rmse)
    if kept_seed:
        M_target_seeded, reg = np.eye(4), seed_eval
    T_target_seeded = RigidTransform.from_matrix(M_target_seeded)  # seeded: the source moved by T_target_source_init
    centre = np.asarray(crop_center_m, float) if crop_center_m is not None else tgt.mean(axis=0)
    return RegistrationResult(
        T_target_source=T_target_seeded @ T_target_source_init,
        fitness=float(reg.fitness),
        inlier_rmse_m=float(reg.inlier_rmse),
        n_source=n_s,
        n_target=n_t,
        correction_rad=T_target_seeded.rotation_angle_rad(),
        correction_m=float(np.linalg.norm(T_target_seeded.apply(centre) - centre)),
        kept_seed=kept_seed,
    )
