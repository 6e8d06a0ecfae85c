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


def register_clouds(
    source_m: np.ndarray,
    target_m: np.ndarray,
    T_init: RigidTransform,
    method: str = "point-to-plane",
    scales_m: tuple = (0.04, 0.02, 0.01),
    crop_center_m: Optional[np.ndarray] = None,
    crop_radius_m: Optional[float] = None,
    max_iterations: int = 25,
    max_corr_voxels: float = 1.5,
    min_fitness_gain: float = 0.01,
    min_rmse_gain: float = 0.05,
) -> RegistrationResult:
    """Align ``source_m`` ``(N, 3)`` to ``target_m`` ``(M, 3)`` starting from ``T_init`` (``T_target_source``).

    Coarse-to-fine ICP over voxel sizes ``scales_m``; the correspondence
    distance at each scale is ``max_corr_voxels`` voxels (1.5: wider lets
    differently-sampled stereo surfaces pull the alignment off, measured on
    simulated sols in docs/handoff.md). ``method`` is ``point-to-plane`` or
    ``generalized`` (GICP). With ``crop_center_m``/``crop_radius_m`` (target
    frame) only points near the centre are used (both clouds, the source after
    applying ``T_init``). The result replaces the seed only if, at the finest
    scale, it raises the fitness by ``min_fitness_gain`` or lowers the inlier
    RMS by the fraction ``min_rmse_gain`` (``kept_seed`` says which).
    """
    import open3d as o3d

    src = np.asarray(source_m, dtype=float)
    tgt = np.asarray(target_m, dtype=float)
    if src.ndim != 2 or src.shape[1] != 3 or tgt.ndim != 2 or tgt.shape[1] != 3:
        raise ValueError("source_m and target_m must be (N, 3)")
    src = src[np.all(np.isfinite(src), axis=1)]
    tgt = tgt[np.all(np.isfinite(tgt), axis=1)]
    src_in_tgt = T_init.apply(src)
    if crop_center_m is not None and crop_radius_m is not None:
        c = np.asarray(crop_center_m, float)
        keep_s = np.linalg.norm(src_in_tgt - c, axis=1) < crop_radius_m
        keep_t = np.linalg.norm(tgt - c, axis=1) < crop_radius_m
        src_in_tgt, tgt = src_in_tgt[keep_s], tgt[keep_t]
    # where the clouds can overlap: each within the other's bounding box, widened by twice the coarsest
    # correspondence distance (points farther out can never pair up; they only cost time)
    margin = 2.0 * max(scales_m) * max_corr_voxels
    if len(src_in_tgt) and len(tgt):
        lo_t, hi_t = tgt.min(axis=0) - margin, tgt.max(axis=0) + margin
        lo_s, hi_s = src_in_tgt.min(axis=0) - margin, src_in_tgt.max(axis=0) + margin
        src_in_tgt = src_in_tgt[np.all((src_in_tgt >= lo_t) & (src_in_tgt <= hi_t), axis=1)]
        tgt = tgt[np.all((tgt >= lo_s) & (tgt <= hi_s), axis=1)]
    if len(src_in_tgt) < 50 or len(tgt) < 50:
        raise ValueError(f"too few points to register ({len(src_in_tgt)} source, {len(tgt)} target)")
    # voxel grids finest first, each coarser one from the finer (cheaper than from the full clouds)
    grids = {}
    ps, pt = _to_o3d(src_in_tgt), _to_o3d(tgt)
    for voxel in sorted(scales_m):
        ps, pt = ps.voxel_down_sample(voxel), pt.voxel_down_sample(voxel)
        grids[voxel] = (ps, pt)
    T = np.eye(4)
    reg = None
    n_s = n_t = 0
    for voxel in scales_m:
        s, t = grids[voxel]
        n_s, n_t = len(s.points), len(t.points)
        if n_s < 20 or n_t < 20:
            continue
        radius = voxel * max_corr_voxels
        crit = o3d.pipelines.registration.ICPConvergenceCriteria(max_iteration=max_iterations)
        if method == "generalized":
            for pc in (s, t):
                pc.estimate_covariances(o3d.geometry.KDTreeSearchParamHybrid(radius=2.5 * voxel, max_nn=30))
            est = o3d.pipelines.registration.TransformationEstimationForGeneralizedICP()
            reg = o3d.pipelines.registration.registration_generalized_icp(s, t, radius, T, est, crit)
        elif method == "point-to-plane":
            t.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2.5 * voxel, max_nn=30))
            est = o3d.pipelines.registration.TransformationEstimationPointToPlane()
            reg = o3d.pipelines.registration.registration_icp(s, t, radius, T, est, crit)
        else:
            raise ValueError(f"unknown registration method {method!r}")
        T = np.asarray(reg.transformation)
    if reg is None:
        raise ValueError("registration had too few points at every scale")
    # keep the seed unless ICP fits the clouds measurably better at the finest scale: on noisy stereo clouds
    # ICP otherwise drifts along weakly constrained directions from an already good seed
    seed_eval = o3d.pipelines.registration.evaluate_registration(s, t, radius, np.eye(4))
    kept_seed = not (reg.fitness > seed_eval.fitness + min_fitness_gain
                     or reg.inlier_rmse < (1.0 - min_rmse_gain) * seed_eval.inlier_rmse)
    if kept_seed:
        T, reg = np.eye(4), seed_eval
    T_corr = RigidTransform.from_matrix(T)
    centre = np.asarray(crop_center_m, float) if crop_center_m is not None else tgt.mean(axis=0)
    return RegistrationResult(
        T_target_source=T_corr @ T_init,
        fitness=float(reg.fitness),
        inlier_rmse_m=float(reg.inlier_rmse),
        n_source=n_s,
        n_target=n_t,
        correction_rad=T_corr.rotation_angle_rad(),
        correction_m=float(np.linalg.norm(T_corr.apply(centre) - centre)),
        kept_seed=kept_seed,
    )
