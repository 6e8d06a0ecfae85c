"""Global registration of two point clouds: FPFH features and a seeded RANSAC (pure numerics).

An answer that does not start from the seed, to check the seeded ICP of :mod:`scipctl.core.registration`
against. Features are Open3D's FPFH (Rusu et al. 2009) on voxel-gridded clouds whose normals point towards
each cloud's sensor; matches are mutual nearest neighbours in feature space (scipy's k-d tree);
the rigid transform is found by RANSAC over those matches, written here in numpy:

* Open3D's own RANSAC (``registration_ransac_based_on_feature_matching``) draws its samples in parallel
  threads from one shared generator, so its answer depends on thread timing; here the samples come from
  ``np.random.default_rng(seed)`` over the matches in a fixed order (source point order, which the voxel grid
  fixes), so the same clouds give the same bits whatever the thread count;
* each minimal sample (3 matches) must have edges of nearly equal length in both clouds (the edge-length
  test of Open3D's checker), then the hypotheses are scored by truncated squared residuals (MSAC), so two
  hypotheses with the same inlier count are ranked by their fit, not by the order they were drawn in: all of
  them on a fixed, seeded subset of the matches, the best ``finalists`` on every match (preemptive scoring);
* the best hypothesis is refitted on its inliers until the set stops changing (LO-RANSAC, as
  :mod:`scipctl.core.ransac` does in 2-D).

Every step is deterministic for given inputs: Open3D's voxel grid, normals and FPFH compute each point on its
own (no reduction across threads), the k-d tree answers do not depend on threads, and the numpy steps run in
one thread.

With ``prior`` (a seed ``T_target_source`` and a radius), only the matches whose points lie within the radius
of each other once the source is moved by the seed are used: the answer is still independent of the ICP's
path (it does not descend from the seed), but it cannot be a symmetric copy of the scene the seed's error
could never reach.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Optional

import numpy as np

from .transforms import RigidTransform


@dataclass(frozen=True)
class GlobalRegistrationParams:
    """Parameters of :func:`global_registration` (lengths in voxels of ``voxel_m``)."""

    voxel_m: float = 0.06  # feature grid: FPFH needs a few voxels across a rock
    normal_radius_voxels: float = 2.5
    feature_radius_voxels: float = 5.0
    feature_max_nn: int = 60
    samples: int = 60000  # minimal samples drawn (most fail the edge-length test)
    inlier_voxels: float = 1.5  # a match is an inlier when the moved source point is this near its target point
    edge_ratio: float = 0.9  # the minimal sample's edges: shorter / longer >= this in both clouds
    min_edge_voxels: float = 2.0  # ... and every edge at least this long (collinear or tiny samples are ill posed)
    min_inliers: int = 12  # fewer: no answer
    refine_iterations: int = 20  # LO refits of the best hypothesis
    preview_matches: int = 200  # every hypothesis is scored on this many matches first ...
    finalists: int = 50  # ... and the best this many on all of them
    chunk: int = 2000  # hypotheses scored per block (memory: chunk x matches x 3 floats)
    seed: int = 0

    def check(self) -> "GlobalRegistrationParams":
        """Raise ``ValueError`` naming the first parameter out of its range; return ``self``."""
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)):
                raise ValueError(f"GlobalRegistrationParams.{f.name} = {v!r}: must be a finite number")
        for name in ("voxel_m", "normal_radius_voxels", "feature_radius_voxels", "inlier_voxels", "min_edge_voxels"):
            if not getattr(self, name) > 0:
                raise ValueError(f"GlobalRegistrationParams.{name} = {getattr(self, name)!r}: must be > 0")
        for name in ("feature_max_nn", "samples", "min_inliers", "refine_iterations", "preview_matches", "finalists",
                     "chunk"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ValueError(f"GlobalRegistrationParams.{name} = {v!r}: must be a whole number >= 1")
        if self.min_inliers < 3:
            raise ValueError(f"GlobalRegistrationParams.min_inliers = {self.min_inliers!r}: must be >= 3")
        if not 0 < self.edge_ratio < 1:
            raise ValueError(f"GlobalRegistrationParams.edge_ratio = {self.edge_ratio!r}: must be in (0, 1)")
        if not (isinstance(self.seed, int) and self.seed >= 0):
            raise ValueError(f"GlobalRegistrationParams.seed = {self.seed!r}: must be a whole number >= 0")
        return self


@dataclass(frozen=True)
class GlobalRegistrationResult:
    """``T_target_source`` (None when no hypothesis reached ``min_inliers``); the feature clouds' sizes, the
    matches used, and the answer's inliers among them (``inlier_rmse_m`` over those)."""

    T_target_source: Optional[RigidTransform]
    n_source: int
    n_target: int
    n_matches: int
    n_inliers: int
    inlier_rmse_m: float

    @property
    def inlier_fraction(self) -> float:
        """Inliers over matches (0 with no matches)."""
        return self.n_inliers / self.n_matches if self.n_matches else 0.0


def fpfh_features(points_m: np.ndarray, origin_m: np.ndarray, params: GlobalRegistrationParams):
    """Voxel-gridded points ``(N, 3)`` and their FPFH features ``(N, 33)`` (normals towards ``origin_m`` (3,),
    the sensor)."""
    from .open3d_import import open3d

    o3d = open3d()

    v = params.voxel_m
    pc = o3d.geometry.PointCloud()
    pc.points = o3d.utility.Vector3dVector(np.ascontiguousarray(points_m, dtype=np.float64))
    pc = pc.voxel_down_sample(v)
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=params.normal_radius_voxels * v, max_nn=30))
    pc.orient_normals_towards_camera_location(np.asarray(origin_m, dtype=np.float64).reshape(3))
    feat = o3d.pipelines.registration.compute_fpfh_feature(
        pc, o3d.geometry.KDTreeSearchParamHybrid(radius=params.feature_radius_voxels * v, max_nn=params.feature_max_nn))
    return np.asarray(pc.points).copy(), np.ascontiguousarray(np.asarray(feat.data).T)


def kabsch(P: np.ndarray, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotations and translations with ``Q ~ R P + t`` for stacks of point sets ``P``, ``Q``
    ``(K, n, 3)``: ``R`` ``(K, 3, 3)`` (proper rotations), ``t`` ``(K, 3)``."""
    cp, cq = P.mean(axis=1), Q.mean(axis=1)
    H = np.einsum("kni,knj->kij", P - cp[:, None], Q - cq[:, None])
    U, _, Vt = np.linalg.svd(H)
    V, Ut = np.swapaxes(Vt, 1, 2), np.swapaxes(U, 1, 2)
    d = np.sign(np.linalg.det(V @ Ut))
    d[d == 0] = 1.0
    R = V @ (np.concatenate([np.ones((len(P), 2)), d[:, None]], axis=1)[:, :, None] * Ut)
    t = cq - np.einsum("kij,kj->ki", R, cp)
    return R, t


def mutual_matches(feat_source: np.ndarray, feat_target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(source, target)`` of mutual nearest neighbours in feature space, in source order."""
    from scipy.spatial import cKDTree

    if len(feat_source) == 0 or len(feat_target) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    _, j = cKDTree(feat_target).query(feat_source, k=1)
    matched, inv = np.unique(j, return_inverse=True)  # each matched target feature queried back once
    _, back = cKDTree(feat_source).query(feat_target[matched], k=1)
    si = np.flatnonzero(back[inv.reshape(-1)] == np.arange(len(feat_source)))
    return si, j[si]


def _edges(X: np.ndarray) -> np.ndarray:
    """Edge lengths ``(K, 3)`` of triangles ``(K, 3, 3)``."""
    return np.stack([np.sqrt(((X[:, a] - X[:, b]) ** 2).sum(axis=1)) for a, b in ((0, 1), (1, 2), (0, 2))], axis=1)


def ransac_rigid(A: np.ndarray, B: np.ndarray, params: GlobalRegistrationParams):
    """Seeded MSAC + local optimisation of a rigid ``B ~ R A + t`` from matched points ``A``, ``B`` ``(N, 3)``.

    Returns ``(M (4, 4) or None, inlier mask (N,))``."""
    p = params
    n = len(A)
    none = (None, np.zeros(n, bool))
    if n < max(3, p.min_inliers):
        return none
    thr2 = (p.inlier_voxels * p.voxel_m) ** 2
    rng = np.random.default_rng(p.seed)
    S = rng.integers(0, n, size=(p.samples, 3))
    P, Q = A[S], B[S]
    eP, eQ = _edges(P), _edges(Q)
    good = np.all((np.minimum(eP, eQ) >= p.edge_ratio * np.maximum(eP, eQ))
                  & (np.minimum(eP, eQ) > p.min_edge_voxels * p.voxel_m), axis=1)
    if not good.any():
        return none
    R, t = kabsch(P[good], Q[good])

    def msac(Rs, ts, A_, B_):
        """Truncated squared residuals of each hypothesis ``(K,)`` over the matches ``A_``, ``B_``."""
        scores = np.empty(len(Rs))
        for k0 in range(0, len(Rs), p.chunk):
            Y = np.matmul(A_[None], np.swapaxes(Rs[k0:k0 + p.chunk], 1, 2)) + ts[k0:k0 + p.chunk, None]
            scores[k0:k0 + p.chunk] = np.minimum(((Y - B_[None]) ** 2).sum(axis=2), thr2).sum(axis=1)
        return scores

    # preemptive scoring: every hypothesis on a fixed subset of the matches, the best few on all of them
    sub = rng.permutation(n)[:p.preview_matches]
    order = np.argsort(msac(R, t, A[sub], B[sub]), kind="stable")[:p.finalists]
    full = msac(R[order], t[order], A, B)
    best_k = int(order[int(np.argmin(full))])  # the first of equal scores: fixed by the draw order
    Rb, tb = R[best_k], t[best_k]
    inl = ((A @ Rb.T + tb - B) ** 2).sum(axis=1) < thr2
    for _ in range(p.refine_iterations):
        if inl.sum() < 3:
            break
        R1, t1 = kabsch(A[inl][None], B[inl][None])
        Rb, tb = R1[0], t1[0]
        new = ((A @ Rb.T + tb - B) ** 2).sum(axis=1) < thr2
        if np.array_equal(new, inl):
            break
        inl = new
    if inl.sum() < p.min_inliers:
        return none
    M = np.eye(4)
    M[:3, :3], M[:3, 3] = Rb, tb
    return M, inl


def global_registration(source_m: np.ndarray, source_origin_m, target_m: np.ndarray, target_origin_m,
                        params: Optional[GlobalRegistrationParams] = None,
                        prior: Optional[tuple] = None) -> GlobalRegistrationResult:
    """``T_target_source`` aligning ``source_m`` ``(N, 3)`` (seen from ``source_origin_m`` (3,), source frame)
    with ``target_m`` ``(M, 3)`` (seen from ``target_origin_m`` (3,), target frame) from FPFH matches alone.

    ``prior``: ``(T_target_source_seed, radius_m)``: use only the matches whose points are within ``radius_m``
    of each other once the source is moved by the seed. Non-finite points are dropped.
    """
    p = (params or GlobalRegistrationParams()).check()
    src = np.asarray(source_m, float)
    tgt = np.asarray(target_m, float)
    if src.ndim != 2 or src.shape[1] != 3 or tgt.ndim != 2 or tgt.shape[1] != 3:
        raise ValueError("source_m and target_m must be (N, 3)")
    src = src[np.isfinite(src).all(axis=1)]
    tgt = tgt[np.isfinite(tgt).all(axis=1)]
    ps, fs = fpfh_features(src, source_origin_m, p)
    pt, ft = fpfh_features(tgt, target_origin_m, p)
    si, ti = mutual_matches(fs, ft)
    if prior is not None:
        T_target_source_seed, radius_m = prior
        if not (np.isfinite(radius_m) and radius_m > 0):
            raise ValueError(f"prior radius must be finite and > 0, got {radius_m!r}")
        near = np.sqrt(((T_target_source_seed.apply(ps[si]) - pt[ti]) ** 2).sum(axis=1)) < radius_m
        si, ti = si[near], ti[near]
    A, B = ps[si], pt[ti]
    M, inl = ransac_rigid(A, B, p)
    if M is None:
        return GlobalRegistrationResult(None, len(ps), len(pt), len(si), 0, float("nan"))
    res = A[inl] @ M[:3, :3].T + M[:3, 3] - B[inl]
    return GlobalRegistrationResult(RigidTransform.from_matrix(M), len(ps), len(pt), len(si), int(inl.sum()),
                                    float(np.sqrt((res ** 2).sum(axis=1).mean())))
